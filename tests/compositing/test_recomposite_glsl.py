"""The GLSL recompositing path (shaders/rokeby_recomposite_frag.glsl) against the Rust
core's ``recomposite``: the same shader file Blender would load, compiled by moderngl on a headless
EGL context (Mesa llvmpipe here)."""

from __future__ import annotations


import numpy as np
import pytest

moderngl = pytest.importorskip("moderngl")
rn = pytest.importorskip("rokeby_native")

from support import bench_module  # noqa: E402
from support.recomposite_frames import bad_inputs, frame, passes_and_reconstruction  # noqa: E402
from rokeby import compositing as C  # noqa: E402
from rokeby.compositing import gl as GL  # noqa: E402


@pytest.fixture(scope="module")
def gl():
    try:
        return GL.GLRecompositor()
    except Exception as exc:  # no EGL/OpenGL 3.3 on this machine
        pytest.skip(f"no headless OpenGL context: {exc}")


def test_unmodified_normals_give_the_input_back_bit_for_bit(gl):
    (ids, n, e, view, d0, r0, img, patches), kw = frame()
    out, st = gl(ids, n, n, view, d0, r0, img, patches, **kw)
    # Exact, not within rounding: the shader returns I untouched where ñ == n (as the Rust core does).
    np.testing.assert_array_equal(out, img)
    ref, rst = rn.compositing.recomposite(ids, n, n, view, d0, r0, img, patches, **kw)
    np.testing.assert_array_equal(out, ref)
    assert st == {"edited": 0, "masked": 0} == dict(rst)


@pytest.mark.parametrize("opts", [{}, {"k_d": 0.7, "k_r": 1.3, "gamma": 2.2}, {"epsilon": 0.2}])
def test_multi_patch_frame_agrees_with_rust(gl, opts):
    (ids, n, e, view, d0, r0, img, patches), kw = frame()
    ref, rst = rn.compositing.recomposite(ids, n, e, view, d0, r0, img, patches, **kw, **opts)
    out, st = gl(ids, n, e, view, d0, r0, img, patches, **kw, **opts)
    assert st == dict(rst) and st["edited"] > 4000 and st["masked"] >= 2
    assert np.isnan(out).sum() == np.isnan(ref).sum() == 0
    err = np.abs(out.astype(np.float64) - ref) / (1 + np.abs(ref))
    # float32 shader vs f64 core, measured: ≤ 2e-6 relative, 2.1e-5 with ε = 0.2 (the asin branch of v).
    print("GLSL vs Rust, max relative error:", err.max())
    assert err.max() < 1e-4, err.max()
    changed = np.abs(ref - img).max(-1) > 1e-3
    assert changed.sum() > 3000
    untouched = (ids < 0) | (ids >= 5) | (ids == 3)
    np.testing.assert_array_equal(out[untouched], img[untouched])


def test_constant_view_and_no_optional_buffers(gl):
    (ids, n, e, view, d0, r0, img, patches), _ = frame(seed=5)
    v = np.array([0.0, 0.0, 1.0])
    ref, rst = rn.compositing.recomposite(ids, n, e, v, d0, r0, img, patches)
    out, st = GL.recomposite_gpu(ids, n, e, v, d0, r0, img, patches)
    assert st == dict(rst)
    assert (np.abs(out.astype(np.float64) - ref) / (1 + np.abs(ref))).max() < 1e-4


def test_reconstructed_sphere_edited_by_emboss(gl):
    """A 'real' chain: SH fit and reflection map reconstructed from a shaded bumpy sphere, then the
    normals embossed; GLSL and Rust recomposite the same frame."""
    bc = bench_module("compositing")

    rng = np.random.default_rng(2016)
    n, inside, d0, r, r0, depth = bc.bumpy_sphere(128, rng)
    fit = rn.compositing.sh_fit(n[inside], d0[inside], "ls")
    env = rn.compositing.reflection_env(r, r0, inside.astype(np.float32), depth, size=64)["map"]
    ids = np.where(inside, 0, -1).astype(np.int32)
    e = C.emboss(n, 0.5, inside)
    img = d0 + r0
    args = (ids, n, e, np.array([0, 0, 1.0]), d0, r0, img, [{"sh": fit["coeffs"], "env": env}])
    ref, rst = rn.compositing.recomposite(*args)
    out, st = gl(*args)
    assert st == dict(rst) and st["edited"] > 5000
    assert (np.abs(out.astype(np.float64) - ref) / (1 + np.abs(ref))).max() < 1e-4


def test_bad_inputs_are_named(gl):
    base, bad = bad_inputs()
    for change, msg in bad:
        with pytest.raises(C.CompositingError, match=msg):
            gl(**{**base, **change})


def _session_edits(n, e):
    """An artist's slider loop: (edited normals, k_D, k_R) per frame, ending with no edit."""
    return [(e, 1.0, 1.0), (C.emboss(n, 0.3), 0.7, 1.3), (C.emboss(n, 0.6), 1.0, 0.0), (n, 1.0, 1.0)]


def test_session_uploads_only_the_edited_normals_and_matches_one_shot_calls(gl):
    """RecompositeSession on moderngl: each frame equals the one-shot CPU result; after the first
    frame one texture is written per frame (the edited normals) instead of twelve; a frame of
    another session drawn in between makes the next one write everything again, still right."""
    args, kw = frame()
    p, rec = passes_and_reconstruction(args, kw)
    n, e = args[1], args[2]
    session = C.RecompositeSession(p, rec, backend="moderngl")
    p2, rec2 = passes_and_reconstruction(*frame(seed=9))
    other = C.RecompositeSession(p2, rec2, backend="moderngl")
    writes = []
    for k, (edit, k_d, k_r) in enumerate(_session_edits(n, e)):
        if k == 2:
            other(C.emboss(rec2.normals, 0.5))
        before = GL.gl_recompositor().uploads
        out, st = session(edit, k_d=k_d, k_r=k_r)
        writes.append(GL.gl_recompositor().uploads - before)
        ref, rst = C.recomposite(p, rec, edit, k_d=k_d, k_r=k_r, backend="cpu")
        assert st == dict(rst)
        assert (np.abs(out.astype(np.float64) - ref) / (1 + np.abs(ref))).max() < 1e-4
    np.testing.assert_array_equal(out, p.image)  # the last frame: unmodified normals, I bit for bit
    assert writes == [12, 1, 12, 1]
    with pytest.raises(C.CompositingError, match="edited_normals: expected shape"):
        session(e[:, :-1])
    with pytest.raises(C.CompositingError, match="k_d"):
        session(e, k_d=float("nan"))
    again, _ = session(e)  # a refused frame changes nothing: the session goes on
    ref, _ = C.recomposite(p, rec, e, backend="cpu")
    assert (np.abs(again.astype(np.float64) - ref) / (1 + np.abs(ref))).max() < 1e-4


def test_shader_files_live_in_shaders():
    from rokeby.core.shaders import shader_dir

    vs, fs = GL.recomposite_sources()
    d = shader_dir()
    assert (d / "rokeby_recomposite_frag.glsl").read_text() in fs
    assert (d / "rokeby_recomposite_vert.glsl").read_text() in vs
