"""rokeby_native.compositing.Recompositor (the passes held by the Rust core between edits) against the one-shot
``rokeby_native.compositing.recomposite`` (the oracle): the same pixels for whole frames and windows, into the
caller's buffer; bad input refused by name; and RecompositeSession / the brush on top of it."""

import sys
from pathlib import Path

import numpy as np
import pytest
import rokeby_native as rn

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))


def _frame(h=200, w=97, patches=4, seed=3):
    """A frame like the bench's (bench/compositing.py hd_frame; 80-row margins), small: vertical patches with an
    SH and a map each, the last one without a reconstruction, smooth normals edited in the top
    half, a NaN diffuse pixel."""
    from compositing import hd_frame

    args, kw = hd_frame(np.random.default_rng(seed), w, h, patches, env_size=16)
    args = list(args)
    args[7] = args[7][:-1] + [None]
    args[4] = args[4].copy()
    args[4][h // 4, w // 3] = np.nan
    return args, kw


def _session(args, kw, **extra):
    ids, n, _e, view, d0, r0, img, pts = args
    return rn.compositing.Recompositor(ids, n, view, d0, r0, img, pts, **kw, **extra)


@pytest.mark.parametrize("prepared", [True, False])
@pytest.mark.parametrize("gamma, k_d, k_r", [(1.0, 1.0, 1.0), (2.2, 1.0, 1.0), (1.0, 1.4, 0.6)])
def test_whole_frame_and_windows_equal_one_shot_recompositing(gamma, k_d, k_r, prepared):
    args, kw = _frame()
    ids, n, e, view, d0, r0, img, pts = args
    ref, rst = rn.compositing.recomposite(*args, **kw, k_d=k_d, k_r=k_r, gamma=gamma)
    assert rst["edited"] > 1000 and rst["masked"] > 0
    s = _session(args, kw, gamma=gamma, prepared=prepared)
    assert s.shape == ids.shape
    # The per-pixel terms that do not depend on ñ: unit n, unit v (a view per pixel here), eq. 5's
    # subtracted term (9 floats) and a validity byte per pixel, in blocks of 64 pixels.
    assert s.prepared_bytes == (37 * -(-ids.size // 64) * 64 if prepared else 0)
    out = np.full_like(img, -5.0)
    st = s.run(out, e, k_d=k_d, k_r=k_r)
    assert st == rst
    # 1e-5 relative is the goal; it is the same kernel, so bit for bit.
    assert out.tobytes() == ref.tobytes()
    # The same buffer again, after another edit in between: nothing left over.
    s.run(out, n, k_d=k_d, k_r=k_r)
    s.run(out, e, k_d=k_d, k_r=k_r)
    assert out.tobytes() == ref.tobytes()
    # A window: into a window-shaped array, and in place into a whole image (only the window written).
    rows, cols = slice(70, 120), slice(13, 90)
    small = np.zeros((50, 77, 3), np.float32)
    s.run(small, e[rows, cols], rows, cols, k_d=k_d, k_r=k_r)
    assert small.tobytes() == np.ascontiguousarray(ref[rows, cols]).tobytes()
    whole = np.full_like(img, -5.0)
    s.run(whole, e, (70, 120), (13, 90), k_d=k_d, k_r=k_r)
    inside = np.zeros(ids.shape, bool)
    inside[rows, cols] = True
    assert whole[inside].tobytes() == ref[inside].tobytes()
    assert (whole[~inside] == -5.0).all()
    # ñ given with a window is kept: None reads it again.
    again = np.zeros_like(small)
    s.run(again, None, rows, cols, k_d=k_d, k_r=k_r)
    assert again.tobytes() == small.tobytes()


def test_new_patches_and_identity():
    args, kw = _frame()
    ids, n, e, view, d0, r0, img, pts = args
    s = _session(args, kw)
    out = np.empty_like(img)
    st = s.run(out, n)
    assert out.tobytes() == img.tobytes() and st["edited"] == 0  # unmodified normals: the render, bit for bit
    swapped = pts[::-1]
    s.set_patches(swapped)
    s.run(out, e)
    ref, _ = rn.compositing.recomposite(ids, n, e, view, d0, r0, img, swapped, **kw)
    assert out.tobytes() == ref.tobytes()


def test_bad_input_is_refused_by_name():
    args, kw = _frame(h=170, w=20, patches=2)
    ids, n, e, view, d0, r0, img, pts = args
    h, w = ids.shape
    with pytest.raises(ValueError, match=r"diffuse: expected shape \(170, 20, 3\)"):
        rn.compositing.Recompositor(ids, n, view, d0[:-1], r0, img, pts)
    with pytest.raises(ValueError, match=r"ids: expected shape \(170, 20\)"):
        rn.compositing.Recompositor(ids[:-1], n, view, d0, r0, img, pts)
    bad = [{"sh": np.full((3, 9), np.nan), "env": None}]
    with pytest.raises(ValueError, match=r"patches\[0\]\.sh: expected finite coefficients"):
        rn.compositing.Recompositor(ids, n, view, d0, r0, img, bad)
    nan_map = [{"sh": None, "env": np.full((2, 8, 8, 3), np.nan, np.float32)}]
    with pytest.raises(ValueError, match=r"patches\[0\]\.env: value 0 is not finite"):
        rn.compositing.Recompositor(ids, n, view, d0, r0, img, nan_map)
    with pytest.raises(ValueError, match="gamma: must be in"):
        _session(args, kw, gamma=0.0)
    s = _session(args, kw)
    with pytest.raises(ValueError, match=r"patches\[0\]\.sh"):
        s.set_patches(bad)
    out = np.empty_like(img)
    with pytest.raises(ValueError, match=r"edited_normals: expected shape \(170, 20, 3\)"):
        s.run(out, e[:, :-1])
    with pytest.raises(ValueError, match=r"out: expected shape \(170, 20, 3\)"):
        s.run(np.empty((170, 19, 3), np.float32), e)
    with pytest.raises(TypeError, match="out: must be a float32"):
        s.run(np.empty((170, 20, 3)), e)
    with pytest.raises(ValueError, match="out: must be C-contiguous"):
        s.run(np.empty((20, 170, 3), np.float32).transpose(1, 0, 2), e)
    ro = np.empty_like(img)
    ro.flags.writeable = False
    with pytest.raises(ValueError, match="out: must be writable"):
        s.run(ro, e)
    with pytest.raises(ValueError, match="out: must be writable and not one of the inputs"):
        s.run(e, e)
    for rows in ((0, 171), slice(5, 5), slice(0, 12, 2), (3, 1)):
        with pytest.raises(ValueError, match="rows: expected a slice with step 1"):
            s.run(out, e, rows)
    with pytest.raises(ValueError, match="k_d"):
        s.run(out, e, k_d=float("nan"))
    # k_D too large for float32 (at γ = 1 too): refused naming the pixel, not inf in the image.
    with pytest.raises(ValueError, match=r"pixel \d+ overflows float32"):
        s.run(out, e, k_d=3e38)
    # The session goes on after the errors.
    s.run(out, e)
    assert out.tobytes() == rn.compositing.recomposite(*args, **kw)[0].tobytes()


def test_recompose_session_and_brush_use_the_core_session():
    """RecompositeSession's CPU frames and windows (what the brush calls per dab) equal the
    one-shot core, written into the caller's buffer; overflow is a CompositingError."""
    from support.recomposite_frames import frame, passes_and_reconstruction
    from rokeby import compositing as C

    args, kw = frame()
    p, rec = passes_and_reconstruction(args, kw)
    ids, n, e, view, d0, r0, img, patches = args
    session = C.RecompositeSession(p, rec)
    alpha_d = np.clip(p.ao.mean(-1), 0, 1)
    ref, rst = rn.compositing.recomposite(ids, n, e, view, d0, r0, img, patches, alpha_d=alpha_d, alpha_r=kw["alpha_r"],
                              diffuse_color=kw["diffuse_color"], reflection_color=kw["reflection_color"])
    buf = session.buffer
    out, st = session(e, out=buf)
    assert out is buf and out.tobytes() == ref.tobytes() and st == rst
    h, w = n.shape[:2]
    rows, cols = slice(h // 4, h // 2), slice(w // 3, w - 2)
    win, _ = session.window(e[rows, cols], rows, cols)
    assert win.tobytes() == np.ascontiguousarray(ref[rows, cols]).tobytes()
    image = img.copy()
    session.window(e, rows, cols, out=image)
    assert image[rows, cols].tobytes() == np.ascontiguousarray(ref[rows, cols]).tobytes()
    with pytest.raises(C.CompositingError, match="edited_normals: expected shape"):
        session.window(e[:3], rows, cols)
    assert session(e)[0].tobytes() == ref.tobytes()
    # A huge (finite) diffuse pass times k_D overflows float32: a CompositingError, no inf image.
    edited = (ids == 0) & (e != n).any(-1) & (p.diff_col.min(-1) > 0.1) & np.isfinite(p.diff_dir).all(-1)
    r, c = np.argwhere(edited)[0]
    p.diff_dir[r, c] = 1e35
    with pytest.raises(C.CompositingError, match=f"pixel {r * w + c} overflows float32"):
        C.RecompositeSession(p, rec)(e, k_d=1e4)
