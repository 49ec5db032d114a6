"""Run by tests/compositing/test_recomposite_blender_gpu.py in a fresh bpy process: the recompositing shader
(shaders/rokeby_recomposite_*.glsl) compiled and drawn by Blender's own gpu module
(rokeby.recomposite_gpu), offscreen, against the Rust core on the frames of
tests/compositing/test_recomposite_glsl.py. The GPU context comes from one tiny EEVEE render
(recomposite_gpu.ensure_context). Prints RESULT {...} (JSON)."""

import json

import numpy as np
import bpy


import rokeby_native as rn  # noqa: E402
from support import bench_module  # noqa: E402
from support.recomposite_frames import bad_inputs, frame, passes_and_reconstruction  # noqa: E402
from rokeby import compositing as C  # noqa: E402
from rokeby.compositing.gl import _CurrentGL  # noqa: E402
from rokeby import recomposite_gpu as G  # noqa: E402

OPTIONS = [{}, {"k_d": 0.7, "k_r": 1.3, "gamma": 2.2}, {"epsilon": 0.2}]


def rel(out, ref):
    return float((np.abs(out.astype(np.float64) - ref) / (1 + np.abs(ref))).max())


def main():
    res = {}
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scenes = sorted(s.name for s in bpy.data.scenes)
    # Before anything has drawn (background mode): no context, and an error that says what to do.
    res["has_context_before"] = G.has_context()
    (ids, n, e, view, d0, r0, img, patches), kw = frame(h=16, w=24)
    try:
        G.recomposite_blender(ids, n, e, view, d0, r0, img, patches)
        res["no_context_error"] = None
    except G.NoGPUContext as exc:
        res["no_context_error"] = str(exc)
    try:
        G.ensure_context()
    except G.NoGPUContext as exc:
        res["skip"] = f"no GPU context after an EEVEE render: {exc}"
        print("RESULT " + json.dumps(res))
        return
    res["has_context_after"] = G.has_context()
    res["scenes_kept"] = sorted(s.name for s in bpy.data.scenes) == scenes
    rc = G.BlenderRecompositor()
    res["renderer"] = rc.renderer

    (ids, n, e, view, d0, r0, img, patches), kw = frame()
    out, st = rc(ids, n, n, view, d0, r0, img, patches, **kw)
    ref, rst = rn.recomposite(ids, n, n, view, d0, r0, img, patches, **kw)
    res["identity"] = {"equal_input": bool(np.array_equal(out, img)), "equal_rust": bool(np.array_equal(out, ref)),
                       "stats": st, "rust_stats": dict(rst), "dtype": str(out.dtype), "shape": list(out.shape)}

    untouched = (ids < 0) | (ids >= 5) | (ids == 3)
    res["frames"] = []
    for opts in OPTIONS:
        ref, rst = rn.recomposite(ids, n, e, view, d0, r0, img, patches, **kw, **opts)
        out, st = rc(ids, n, e, view, d0, r0, img, patches, **kw, **opts)
        again, _ = rc(ids, n, e, view, d0, r0, img, patches, **kw, **opts)
        res["frames"].append({"opts": opts, "stats": st, "rust_stats": dict(rst), "rel": rel(out, ref),
                              "nan": int(np.isnan(out).sum()), "rust_nan": int(np.isnan(ref).sum()),
                              "changed": int((np.abs(ref - img).max(-1) > 1e-3).sum()),
                              "untouched_equal": bool(np.array_equal(out[untouched], img[untouched])),
                              "repeat_equal": bool(np.array_equal(out, again))})

    # The same shader on moderngl/EGL (when there is one) gives the same pixels, and using it in this
    # process leaves Blender's context current (Blender's next draw is still right).
    before, _ = rc(ids, n, e, view, d0, r0, img, patches, **kw)
    blender_ctx = _CurrentGL().egl
    try:
        gl = C.GLRecompositor()
    except Exception as exc:  # noqa: BLE001 - no moderngl or no EGL: recorded, the test skips that check
        res["moderngl"] = {"error": str(exc)}
    else:
        kept = [_CurrentGL().egl == blender_ctx]
        after_create, _ = rc(ids, n, e, view, d0, r0, img, patches, **kw)
        mgl, _ = gl(ids, n, e, view, d0, r0, img, patches, **kw)
        kept.append(_CurrentGL().egl == blender_ctx)
        after_draw, _ = rc(ids, n, e, view, d0, r0, img, patches, **kw)
        res["moderngl"] = {"rel": rel(before, mgl), "equal": bool(np.array_equal(before, mgl)),
                           "blender_after_equal": bool(np.array_equal(after_create, before) and np.array_equal(after_draw, before)),
                           "blender_context_current": blender_ctx is not None and all(kept)}

    (ids2, n2, e2, _v, d02, r02, img2, patches2), _ = frame(seed=5)
    v = np.array([0.0, 0.0, 1.0])
    ref, rst = rn.recomposite(ids2, n2, e2, v, d02, r02, img2, patches2)
    out, st = G.recomposite_blender(ids2, n2, e2, v, d02, r02, img2, patches2)
    res["constant_view"] = {"stats": st, "rust_stats": dict(rst), "rel": rel(out, ref)}

    bc = bench_module("compositing")

    rng = np.random.default_rng(2016)
    ns, inside, sd0, r, sr0, depth = bc.bumpy_sphere(128, rng)
    fit = rn.sh_fit(ns[inside], sd0[inside], "ls")
    env = rn.reflection_env(r, sr0, inside.astype(np.float32), depth, size=64)["map"]
    sids = np.where(inside, 0, -1).astype(np.int32)
    args = (sids, ns, C.emboss(ns, 0.5, inside), np.array([0, 0, 1.0]), sd0, sr0, sd0 + sr0, [{"sh": fit["coeffs"], "env": env}])
    ref, rst = rn.recomposite(*args)
    out, st = rc(*args)
    res["sphere"] = {"stats": st, "rust_stats": dict(rst), "rel": rel(out, ref)}

    base, bad = bad_inputs()
    res["bad"] = []
    for change, msg in bad:
        try:
            rc(**{**base, **change})
            res["bad"].append({"msg": msg, "raised": None})
        except Exception as exc:  # noqa: BLE001 - recorded and judged by the test
            res["bad"].append({"msg": msg, "raised": type(exc).__name__,
                               "compositing_error": isinstance(exc, C.CompositingError), "text": str(exc)})

    # compositing.recomposite(..., backend=...) on passes and a reconstruction built from the frame.
    p, rec = passes_and_reconstruction((ids, n, e, view, d0, r0, img, patches), kw)
    cpu, cst = C.recomposite(p, rec, e, k_d=0.8, backend="cpu")
    gpu_out, gst = C.recomposite(p, rec, e, k_d=0.8, backend="blender_gpu")
    ident, ist = C.recomposite(p, rec, n, backend="blender_gpu")
    try:
        C.recomposite(p, rec, e, backend="metal")
        unknown = None
    except C.CompositingError as exc:
        unknown = str(exc)
    # A slider loop: RecompositeSession through Blender's gpu module, each frame against the CPU
    # path's one-shot result, and how many textures each frame made (a plain call in between).
    session = C.RecompositeSession(p, rec, backend="blender_gpu")
    br = G.blender_recompositor()
    res["session"] = []
    for k, (edit, k_d, k_r) in enumerate([(e, 1.0, 1.0), (C.emboss(n, 0.3), 0.7, 1.3), (C.emboss(n, 0.6), 1.0, 0.0),
                                          (n, 1.0, 1.0)]):
        if k == 2:
            C.recomposite(p, rec, C.emboss(n, 0.5), backend="blender_gpu")
        before = br.uploads
        out, st = session(edit, k_d=k_d, k_r=k_r)
        ref, rst = C.recomposite(p, rec, edit, k_d=k_d, k_r=k_r, backend="cpu")
        res["session"].append({"made": br.uploads - before, "rel": rel(out, ref), "stats": st, "cpu_stats": rst,
                               "identity_equal": bool(np.array_equal(out, img))})
    res["backend"] = {"rel": rel(gpu_out, cpu), "stats": gst, "cpu_stats": cst,
                      "identity_equal": bool(np.array_equal(ident, img)), "identity_stats": ist, "unknown": unknown}
    print("RESULT " + json.dumps(res))


main()
