"""Viewport preview shader: time per frame of the per-pixel field (shaders/) with moderngl on a
headless EGL context, i.e. Mesa llvmpipe (a CPU rasteriser) on machines without a GPU.

A full frame of reflecting surface (the nefertiti scan filling the view), K constraints, Euclidean
or per-vertex (geodesic) distances; the frame is drawn and finished (glFinish), medians of a few
frames. Printed next to the paper's figures (GTX 260, 1280x960). ``--json PATH`` writes the rows.
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
sys.path.insert(0, str(ROOT / "tests"))

import rokeby_native as rn  # noqa: E402
from support.gl_harness import Renderer, create_context, look_at, perspective  # noqa: E402
from support.reference import random_constraints  # noqa: E402
from rokeby.reflection.viewport import glsl  # noqa: E402
from rokeby.core.meshio import load_obj, vertex_normals  # noqa: E402

SHARED = Path(os.environ.get("ROKEBY_SHARED", ROOT.parent / "shared"))
RESOLUTIONS = ((1280, 720), (1920, 1080))
KS = (1, 8, 32)


def measure(frames: int = 3) -> list:
    ctx = create_context()
    v, f = load_obj(SHARED / "meshes" / "nefertiti.obj")
    n = vertex_normals(v, f)
    centre = v.mean(0)
    size = float(np.linalg.norm(v.max(0) - v.min(0)))
    solver = rn.geometry.GeodesicSolver(v, f)
    rng = np.random.default_rng(2009)
    rows = []
    for w, h in RESOLUTIONS:
        r = Renderer(ctx, w, h)
        r.set_mesh(v, n, f)
        # Look at the face from the front (-Y after the OBJ's axes), close enough to fill the view.
        eye = (centre + np.array([0.0, -0.75 * size, 0.05 * size])).astype(np.float32)
        vp = perspective(40, w / h, 0.01 * size, 10 * size) @ look_at(eye, centre)
        r.set_plan(glsl.plan_field(np.zeros((0, 9)), n_vertices=len(v)))
        coverage = float((r.render(vp, eye, glsl.OUT_POSITION)[..., 3] > 0).mean())
        for k in KS:
            picks = rng.choice(len(v), k, replace=False)
            c = random_constraints(rng, k, 0, max_edit=0.7, min_edit=0.1)
            c[:, :3] = v[picks]
            for metric in ("euclidean", "geodesic"):
                kwargs = {}
                if metric == "geodesic":
                    kwargs["distances"] = solver.distances([int(i) for i in picks], method="dijkstra")
                r.set_plan(glsl.plan_field(c, n_vertices=len(v), **kwargs))
                r.render(vp, eye, glsl.OUT_COLOR)  # compile/warm-up and upload
                times = []
                for _ in range(frames):
                    t = time.perf_counter()
                    r.render(vp, eye, glsl.OUT_COLOR, finish=False)
                    ctx.finish()
                    times.append(time.perf_counter() - t)
                dt = statistics.median(times)
                rows.append({"width": w, "height": h, "k": k, "metric": metric, "ms": dt * 1e3, "fps": 1.0 / dt, "coverage": coverage, "mpix_s": w * h * coverage / dt / 1e6})
                print(f"{w}x{h} K={k:2d} {metric:9s} {dt * 1e3:8.1f} ms  {1 / dt:6.2f} fps  ({coverage:.0%} of the frame is mirror)", flush=True)
    renderer = ctx.info["GL_RENDERER"]
    ctx.release()
    return [{"renderer": renderer, "mesh": f"nefertiti.obj ({len(v):,} vertices)"}] + rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", default=None)
    ap.add_argument("--frames", type=int, default=3)
    args = ap.parse_args()
    rows = measure(args.frames)
    if args.json:
        Path(args.json).write_text(json.dumps(rows))


if __name__ == "__main__":
    main()
