"""Timing: the artist's loop of *Recomposite Render* (rokeby.api.recomposite_exr) on a 1920x1080
frame rendered with the compositing passes: the first edit of the file (reading the EXR and
reconstructing its patches), then each further edit of the same frame (what one change in the
operator's redo panel costs: the normal edit, eqs. 3-5, and writing the Blender image), on the
CPU path and through Blender's gpu module. Runs with bpy (background mode).

    .venv/bin/python bench/composite_edit_loop.py [--size 1920,1080] [--repeat 5] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "addon"))


def scene(w, h):
    """Three shiny objects under the forest world, one Cycles sample (the passes' noise does not
    change the timings)."""
    import bpy

    from rokeby import envmaps

    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.samples, sc.cycles.device, sc.cycles.use_denoising = 1, "CPU", False
    sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = w, h, 100
    envmaps.use_studio_world(sc, "forest")
    for k, (add, loc) in enumerate(((bpy.ops.mesh.primitive_uv_sphere_add, (-1.6, 0, 0)),
                                    (bpy.ops.mesh.primitive_torus_add, (0.9, 0, 0)),
                                    (bpy.ops.mesh.primitive_monkey_add, (0, 0, 1.5)))):
        add(location=loc)
        bpy.ops.object.shade_smooth()
        ob = bpy.context.object
        mat = bpy.data.materials.new(f"m{k}")
        mat.use_nodes = True
        b = mat.node_tree.nodes["Principled BSDF"]
        b.inputs["Base Color"].default_value = ((0.8, 0.3, 0.2, 1), (0.2, 0.5, 0.8, 1), (0.7, 0.7, 0.2, 1))[k]
        b.inputs["Roughness"].default_value = 0.2
        ob.data.materials.append(mat)
    bpy.ops.object.camera_add(location=(0, -7.5, 1.2), rotation=(1.42, 0, 0))
    sc.camera = bpy.context.object
    return sc


def loop(api, C, path, backend, repeat):
    C.close_render()
    t = time.perf_counter()
    _img, first = api.recomposite_exr(path, edit="emboss", amount=0.5, backend=backend)
    first_s = time.perf_counter() - t
    runs = []
    for k in range(repeat):
        t = time.perf_counter()
        _img, st = api.recomposite_exr(path, edit="emboss", amount=0.3 + 0.1 * k, backend=backend)
        runs.append({**{key: st[key] for key in ("open_s", "edit_s", "recomposite_s", "show_s")},
                     "total_s": time.perf_counter() - t, "reused": st["reused"]})
    med = {key: 1e3 * float(np.median([r[key] for r in runs])) for key in ("open_s", "edit_s", "recomposite_s", "show_s", "total_s")}
    return {"first_ms": 1e3 * first_s, "first_open_ms": 1e3 * first["open_s"], "edited": int(first["edited"]),
            "all_reused": all(r["reused"] for r in runs), **{k.replace("_s", "_ms"): v for k, v in med.items()}}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", default="1920,1080")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--json")
    a = ap.parse_args()
    w, h = (int(v) for v in a.size.split(","))
    from rokeby import api
    from rokeby import compositing as C

    res = {"width": w, "height": h, "load_before": os.getloadavg()[0]}
    with tempfile.TemporaryDirectory() as tmp:
        path = str(Path(tmp) / "frame.exr")
        t = time.perf_counter()
        C.render_passes(scene(w, h), path)
        res["render_s"] = time.perf_counter() - t
        res["cpu"] = loop(api, C, path, "cpu", a.repeat)
        try:
            from rokeby.compositing import blender_gpu as G

            G.ensure_context()
            res["blender_gpu"] = loop(api, C, path, "blender_gpu", a.repeat)
            res["renderer"] = G.blender_recompositor().renderer
        except Exception as exc:  # noqa: BLE001 - no GPU context here: say why
            res["blender_gpu_error"] = str(exc)
        C.close_render()
    res["load_after"] = os.getloadavg()[0]
    text = json.dumps(res, indent=1)
    if a.json:
        Path(a.json).write_text(text)
    print("RESULT " + json.dumps(res))


if __name__ == "__main__":
    main()
