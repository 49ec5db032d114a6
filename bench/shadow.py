"""Benchmark: freeform shadow boundary editing against the paper's Table 1.

Mattausch et al. (single core of an i7-3770K + GTX 580): Paolo 30.5k triangles, Bunny 70k,
Dragon 100k; shadow-mesh creation 0.2 s, 1.01 s, 1.28 s; editing and rendering hard shadows
20, 32, 101 ms per frame. Here, on the shared meshes of similar size:

* spot.obj subdivided once (23.4k triangles; the nearest shared size to Paolo's 30.5k),
* stanford-bunny.obj (69.5k; its scan holes closed by fans to their centroids),
* nefertiti.obj (99.9k; closed as shipped),

each scaled to unit radius 1.5 units above a non-planar terrain (a 200x200 height field, 80k
triangles, like the paper's terrain), lit by a point light above and to the side. Timed:

* setup: ShadowEditor (vertex normals given; silhouettes, BVH over terrain + caster, the handle
  check that some receiver is under the light);
* handles: shadow rays of every vertex of the longest loop;
* edit: one drag step of a third of the longest loop (MLS + noise-free, new handles by ray casting)
  — the paper's per-frame editing cost without its rendering;
* shadow mesh: the first shadow_mesh() (cotangent Laplacian in light space, LᵀL assembly, sparse
  Cholesky, solve) — the paper's "smesh"; and a later one (back-substitution only).

    python bench/shadow.py [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path

import numpy as np

import rokeby_native as rn
from rokeby.core.meshio import load_obj, subdivide_midpoint, vertex_normals

ROOT = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("ROKEBY_SHARED", ROOT.parent / "shared"))
PAPER = {"Paolo": (30_500, 0.2, 0.020), "Bunny": (70_000, 1.01, 0.032), "Dragon": (100_000, 1.28, 0.101)}


def close_holes(v, f):
    """Closes every boundary loop by a fan to its centroid (new vertices appended)."""
    f = np.asarray(f, np.int64)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    directed = {tuple(x) for x in e.tolist()}
    nxt = {}
    for a, b in directed:
        if (b, a) not in directed:
            nxt[b] = a  # walk the boundary in the reverse direction: the fan then matches the orientation
    verts = [np.asarray(v, np.float64)]
    faces = [f]
    nv = len(v)
    seen = set()
    for s in list(nxt):
        if s in seen:
            continue
        loop = [s]
        seen.add(s)
        x = nxt[s]
        while x != s and x not in seen and x in nxt:
            loop.append(x)
            seen.add(x)
            x = nxt[x]
        c = verts[0][loop].mean(axis=0) if nv == len(verts[0]) else np.concatenate(verts)[loop].mean(axis=0)
        verts.append(c[None])
        ci = nv
        nv += 1
        faces.append(np.array([[loop[i], loop[(i + 1) % len(loop)], ci] for i in range(len(loop))], np.int64))
    return np.concatenate(verts).astype(np.float32), np.concatenate(faces)


def terrain(n=200, size=8.0):
    xs = np.linspace(-size / 2, size / 2, n + 1)
    X, Y = np.meshgrid(xs, xs)
    Z = 0.15 * np.sin(1.3 * X) * np.cos(0.9 * Y) + 0.05 * np.sin(3.1 * X + 2.0 * Y)
    v = np.stack([X, Y, Z], -1).reshape(-1, 3).astype(np.float32)
    i = np.arange(n)[:, None] * (n + 1) + np.arange(n)[None]
    i = i.ravel()
    f = np.concatenate([np.stack([i, i + 1, i + n + 2], 1), np.stack([i, i + n + 2, i + n + 1], 1)])
    return v, f.astype(np.int64)


def place(v):
    v = v.astype(np.float64)
    c = 0.5 * (v.min(0) + v.max(0))
    r = np.linalg.norm(v - c, axis=1).max()
    return ((v - c) / r + np.array([0.0, 0.0, 1.5])).astype(np.float32)


def timed(fn, repeat=5):
    times, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), out


def models():
    spot_v, spot_f = load_obj(SHARED / "meshes" / "spot.obj")
    spot_v, spot_f = subdivide_midpoint(spot_v, spot_f)
    yield "Paolo", "spot.obj, subdivided once", spot_v, spot_f
    for paper, name in (("Bunny", "stanford-bunny.obj"), ("Dragon", "nefertiti.obj")):
        v, f = load_obj(SHARED / "meshes" / name)
        cv, cf = close_holes(v, f)
        holes = len(cv) - len(v)
        yield paper, f"{name}, {holes} holes closed" if holes else f"{name} (closed)", cv, cf


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    tv, tf = terrain()
    light = np.array([0.8, 0.5, 5.0])
    rows = []
    for paper_name, what, v, f in models():
        v = place(v)
        f = np.asarray(f, np.int64)
        n = vertex_normals(v, f.astype(np.int32))
        row = {"paper": paper_name, "mesh": what, "triangles": int(len(f)), "vertices": int(len(v))}
        try:
            t_setup, ed = timed(lambda: rn.shadows.ShadowEditor(v, f, tv, tf, light_position=light, normals=n, min_loop_vertices=20), repeat=3)
        except ValueError as exc:
            row["error"] = str(exc)
            rows.append(row)
            print(row, flush=True)
            continue
        loops = ed.loops()
        k = int(np.argmax([len(l["points"]) for l in loops]))
        m = len(loops[k]["points"])
        row.update(setup_s=t_setup, loops=len(loops), active_loops=int(sum(l["active"] for l in loops)), loop_vertices=m,
                   silhouette_vertices=int(sum(len(l["points"]) for l in loops)))
        row["handles_s"], h = timed(lambda: ed.handles(k))
        hp = h["points"][h["hit"]]
        centre = hp.mean(axis=0)
        mid = m // 2
        target = centre + (h["points"][mid] - centre) * 1.2
        fixed = (mid - m // 6, mid + m // 6)
        row["edit_s"], _ = timed(lambda: ed.drag(k, fixed, mid, target, style="affine"))
        ed.commit()
        t0 = time.perf_counter()
        sm = ed.shadow_mesh()
        row["smesh_first_s"] = time.perf_counter() - t0
        row["smesh_again_s"], _ = timed(lambda: ed.shadow_mesh())
        row["max_displacement"] = float(np.abs(sm - v).max())
        rows.append(row)
        print(row, flush=True)
    r = {"rows": rows, "paper": PAPER, "threads": os.environ.get("RAYON_NUM_THREADS", str(os.cpu_count())),
         "load_average": os.getloadavg()[0], "cpus": os.cpu_count()}
    if args.json:
        Path(args.json).write_text(json.dumps(r, indent=1))


if __name__ == "__main__":
    main()
