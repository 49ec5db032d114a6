"""Timing: recompositing (eqs. 3-5) of a 1920x1080 frame with ten patches (each an SH and a 128²
map, 43% of the pixels edited; the frame of bench/compositing.py's recompositing row) through
Blender's own gpu module (rokeby.compositing.blender_gpu: the GLSL shader drawn offscreen), beside the
moderngl path and the Rust core in the same process. Runs with bpy (background mode; the GPU
context comes from one tiny EEVEE render).

    .venv/bin/python bench/recomposite_blender_gpu.py [--repeat 5] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
sys.path.insert(0, str(ROOT / "addon"))


def median_ms(fn, repeat):
    ts = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return 1e3 * float(np.median(ts)), 1e3 * float(min(ts))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--json")
    a = ap.parse_args()
    import bpy
    import rokeby_native as rn
    from rokeby.compositing import blender_gpu as G
    from rokeby.compositing import gl as GL

    bpy.ops.wm.read_factory_settings(use_empty=True)
    t = time.perf_counter()
    G.ensure_context()
    t_ctx = time.perf_counter() - t
    t = time.perf_counter()
    rc = G.BlenderRecompositor()
    t_compile = time.perf_counter() - t
    from compositing import hd_frame  # bench/compositing.py: the benchmark's frame

    args, kw = hd_frame(np.random.default_rng(2016))
    out, st = rc(*args, **kw)  # first frame: offscreen, staging arrays
    ref, rst = rn.compositing.recomposite(*args, **kw)
    res = {"renderer": rc.renderer, "context_s": t_ctx, "compile_ms": 1e3 * t_compile, "stats": st,
           "rust_stats": dict(rst), "max_rel_diff": float((np.abs(out.astype(np.float64) - ref) / (1 + np.abs(ref))).max()),
           "load_before": os.getloadavg()[0]}
    stages = []

    def frame():
        rc(*args, **kw)
        stages.append(rc.timings)

    res["blender_gpu_ms"], res["blender_gpu_min_ms"] = median_ms(frame, a.repeat)
    # Where the time goes (medians): checking/packing the inputs, making the textures (Blender's API
    # cannot update one), the draw until its read-back has returned, the status count and copy.
    for key in stages[0]:
        res[f"{key}_ms"] = 1e3 * float(np.median([s[key] for s in stages]))
    res["identity_ms"], _ = median_ms(lambda: rc(args[0], args[1], args[1], *args[3:], **kw), a.repeat)
    # An interactive session's next frame (compositing.RecompositeSession): one texture made (the
    # edited normals) instead of twelve; and the draw with nothing made (shading and read-back).
    f = GL.recomposite_frame(*args, **kw)
    rc.draw(f)
    session = []

    def session_frame():
        f.set_edit(args[2], 1.0, 1.0)
        made = rc.uploads
        rc.draw(f, ("rk_edited",))
        session.append({**rc.timings, "made": rc.uploads - made})

    res["session_ms"], res["session_min_ms"] = median_ms(session_frame, a.repeat)
    for key in ("textures", "draw_read"):
        res[f"session_{key}_ms"] = 1e3 * float(np.median([s[key] for s in session]))
    res["session_textures_made"] = session[-1]["made"]
    res["draw_only_ms"], _ = median_ms(lambda: rc.draw(f, ()), a.repeat)
    try:
        gl = GL.GLRecompositor()
        gl(*args, **kw)
        res["moderngl_ms"], _ = median_ms(lambda: gl(*args, **kw), a.repeat)
    except Exception as exc:  # noqa: BLE001 - no EGL here
        res["moderngl_error"] = str(exc)
    res["rust_ms"], _ = median_ms(lambda: rn.compositing.recomposite(*args, **kw), a.repeat)
    res["load_after"] = os.getloadavg()[0]
    text = json.dumps(res, indent=1)
    if a.json:
        Path(a.json).write_text(text)
    print("RESULT " + text)


if __name__ == "__main__":
    main()
