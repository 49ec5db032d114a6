"""Reflection map versus ray traced render: time against error, Cycles CPU, tiny.

A chrome ball (64x32 UV sphere, smooth) under the forest HDR world, nothing else near it: the map's
only errors are its resolution and, for rough metal, its blurred-level lobe. Reference: the same
ball ray traced at 256 samples. Compared, on the ball (the central disc of the frame):
  * ray traced at 4 / 16 / 64 samples;
  * reflection map captured at 256x128 ... 2048x1024 (16 capture samples; one capture per
    resolution, shared by both roughnesses: the capture hides the mirror), rendered at 16 samples.
Error: mean |pixel - reference| over the ball, 8-bit PNG values in 0-1 (as docs/reflection_maps.md).
Reuses the scene helpers of docs/reflection_maps/make_figures.py and rokeby.api.

    .venv/bin/python bench/reflmap_vs_rt.py --json OUT [--quick]
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
sys.path.insert(0, str(ROOT / "docs" / "reflection_maps"))

import bpy  # noqa: E402

import make_figures as mf  # noqa: E402
from rokeby import api  # noqa: E402

SIZE = 96
REF_SAMPLES = 256
RT_SAMPLES = (4, 16, 64)
MAP_SAMPLES = 16
ROUGHNESS = (0.0, 0.35)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--json", required=True)
    ap.add_argument("--quick", action="store_true", help="skip the 2048-wide capture")
    a = ap.parse_args()
    widths = (256, 512, 1024) + (() if a.quick else (2048,))
    mf.SIZE, mf.SAMPLES = SIZE, MAP_SAMPLES
    load0 = os.getloadavg()[0]
    sc, cam = mf.scene()
    cam.location = (0.0, -4.0, 0.0)
    cam.rotation_euler = (np.pi / 2, 0.0, 0.0)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=64, ring_count=32)
    bpy.ops.object.shade_smooth()
    ball = bpy.context.object
    ball.name = "Ball"
    mat = mf.chrome("Chrome")
    ball.data.materials.append(mat)
    api.add_mirror(ball)
    disc = np.hypot(*np.mgrid[-1:1:SIZE * 1j, -1:1:SIZE * 1j]) < 0.6

    def err(img, ref):
        return float(np.abs(img - ref)[..., :3].mean(-1)[disc].mean())

    def set_roughness(r):
        api.remove_render_nodes(ball)
        mat.node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value = r

    def traced(samples):
        ball.rokeby.render_mode = "RAY_TRACED"
        api.install_render_nodes(ball)
        sc.cycles.samples = samples
        return mf.render("rt")

    rows, refs = [], {}
    mf.render("warmup")
    for r in ROUGHNESS:
        set_roughness(r)
        refs[r], t_ref = traced(REF_SAMPLES)
        rows.append({"roughness": r, "mode": "ray traced", "setting": f"{REF_SAMPLES} samples (reference)", "render_s": t_ref, "capture_s": None, "error": 0.0})
        for s in RT_SAMPLES:
            img, t = traced(s)
            rows.append({"roughness": r, "mode": "ray traced", "setting": f"{s} samples", "render_s": t, "capture_s": None, "error": err(img, refs[r])})
    for w in widths:
        set_roughness(ROUGHNESS[0])
        sc.cycles.samples = MAP_SAMPLES
        t = time.perf_counter()
        api.capture_reflection_map(ball, resolution=w, samples=MAP_SAMPLES)
        t_cap = time.perf_counter() - t
        for r in ROUGHNESS:
            set_roughness(r)
            ball.rokeby.render_mode = "REFLECTION_MAP"
            api.install_render_nodes(ball)
            sc.cycles.samples = MAP_SAMPLES
            img, t = mf.render("map")
            rows.append({"roughness": r, "mode": "reflection map", "setting": f"{w}x{w // 2} map, {MAP_SAMPLES} samples", "width": w,
                         "render_s": t, "capture_s": t_cap, "capture_render_s": float(ball.rokeby.map_capture_seconds), "error": err(img, refs[r])})
    out = {"rows": rows, "size": SIZE, "threads": sc.render.threads, "cpus": os.cpu_count(), "load_average": [load0, os.getloadavg()[0]],
           "blender": bpy.app.version_string}
    Path(a.json).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
