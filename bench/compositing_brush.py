"""Timing: one step of the normal brush (*Paint Normals*, rokeby.compositing.brush) on a
1920x1080 frame: the brush's edit of the dab's window plus eqs. 3-5 on that window
(``BrushSession.extend``), and writing the frame into the Blender image (``show_step``:
foreach_set of the whole image, which keeps the compositor's Image node current), against eqs.
3-5 on the whole frame (what a step would cost without the window). The frame is
bench/compositing.py's (ten patches, SH + 128² map each); strokes of 20 steps 10 pixels apart,
radius 40 pixels. Runs with bpy (background mode). Medians of the steps after the first (the
first step of a smoothing stroke smooths the whole first dab).

    .venv/bin/python bench/compositing_brush.py [--size 1920,1080] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "addon"))
sys.path.insert(0, str(ROOT / "bench"))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", default="1920,1080")
    ap.add_argument("--json")
    a = ap.parse_args()
    w, h = map(int, a.size.split(","))

    import bpy  # noqa: F401 - show_step writes a Blender image

    from compositing import hd_frame
    from rokeby import compositing as C
    from rokeby.compositing import brush as B

    args, kw = hd_frame(np.random.default_rng(1), w=w, h=h)
    ids, n, _e, view, d0, r0, img, patches = args
    z = np.zeros_like(d0)
    p = C.Passes(image=img, normal=n, diff_dir=d0, diff_ind=z, diff_col=kw["diffuse_color"], gloss_dir=r0, gloss_ind=z,
                 gloss_col=kw["reflection_color"], index_ob=np.zeros((h, w), np.float32), index_ma=np.zeros((h, w), np.float32),
                 ao=np.full((h, w, 3), 0.9, np.float32), depth=np.ones((h, w), np.float32), reflocc=kw["alpha_r"],
                 camera_x=z, camera_y=z, incoming_cam=z)
    rec = C.Reconstruction(ids=ids, keys=[], patches=patches, reports=[], normals=n, view=view)
    opened = C.RenderEdit(path="bench", passes=p, reconstruction=rec, session=C.RecompositeSession(p, rec))
    t0 = time.perf_counter()
    s = B.BrushSession(opened, "Rokeby Brush Bench")
    open_s = time.perf_counter() - t0
    full = []
    for _ in range(5):
        t0 = time.perf_counter()
        opened.session(s.layer)
        full.append(time.perf_counter() - t0)
    rows = []
    for mode in B.MODES:
        s.begin(40.0, 0.5, mode)
        ext, show = [], []
        for k in range(20):
            t0 = time.perf_counter()
            s.extend([(h / 2 + 2 * k, w / 3 + 10 * k)])
            t1 = time.perf_counter()
            B.show_step(s)
            t2 = time.perf_counter()
            ext.append(t1 - t0)
            show.append(t2 - t1)
        s.end()
        rows.append({"mode": mode, "first_step_ms": 1e3 * ext[0], "step_ms": 1e3 * statistics.median(ext[1:]),
                     "show_ms": 1e3 * statistics.median(show[1:]), "window_pixels": s.timings["pixels"]})
    out = {"size": [w, h], "open_s": open_s, "whole_frame_ms": 1e3 * statistics.median(full), "rows": rows,
           "threads": os.cpu_count(), "load_average": os.getloadavg()[0]}
    print(f"{w}x{h}: open {open_s:.2f} s, eqs. 3-5 on the whole frame {out['whole_frame_ms']:.1f} ms (median of 5)")
    for r in rows:
        print(f"  {r['mode']:7s} step {r['step_ms']:.1f} ms (first {r['first_step_ms']:.0f} ms, window {r['window_pixels']:,} px), "
              f"write the Blender image {r['show_ms']:.1f} ms; step / whole frame = {r['step_ms'] / out['whole_frame_ms']:.2f}")
    print(f"  load average {out['load_average']:.1f}")
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
