"""What the benchmark sections share: paths, the paper's reference figures, timing, random constraints."""

from __future__ import annotations

import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]  # the checkout
sys.path.insert(0, str(ROOT / "tests"))  # support.reference: the float64 reference of the tests


import rokeby_native as rn  # noqa: E402

from support.reference import random_constraints  # noqa: E402

SHARED = Path(os.environ.get("ROKEBY_SHARED", ROOT.parent / "shared"))


PAPER = {1: 24.5, 32: 18.5}


def timeit(fn, repeat=5):
    fn()  # warm-up (thread pool, caches)
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def constraints(rng, k, spread, centre=None, max_edit=0.7):
    return random_constraints(rng, k, spread=spread, max_edit=max_edit, min_edit=0.1, at=centre)


def full_frame_gbuffer(w, h):
    """Every pixel on a gently curved mirror (a full 1280x960 frame of reflecting surface)."""
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    x, y = xs / w - 0.5, (ys / h - 0.5) * h / w
    z = 0.05 * np.sin(8 * x) + 0.05 * np.cos(6 * y)
    pos = np.stack([x, y, z], -1)
    nrm = np.stack([-0.4 * np.cos(8 * x), 0.3 * np.sin(6 * y), np.ones_like(x)], -1)
    nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
    return pos.astype(np.float32), nrm.astype(np.float32)


def machine():
    cpu = "unknown CPU"
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    import bpy  # noqa: F401 - version only

    return f"{cpu}, {os.cpu_count()} cores; Python {platform.python_version()}, numpy {np.__version__}, rokeby_native {rn.__version__}, Blender {bpy.app.version_string}"


def rel_errors(d, exact, faces, source):
    """Mean and max relative error over vertices outside the source's 1-ring that exact reaches."""
    ring = np.unique(faces[(faces == source).any(axis=1)])
    mask = np.isfinite(exact) & (exact > 0)
    mask[ring] = False
    ok = mask & np.isfinite(d)
    rel = np.abs(d[ok] - exact[ok]) / exact[ok]
    missing = int(np.count_nonzero(mask & ~np.isfinite(d)))
    return float(rel.mean()), float(rel.max()), missing


def against_goal(value: float, goal: float, unit: str, *, at_most: bool = True) -> str:
    """'met' or by how much ``value`` misses ``goal`` (an upper bound when ``at_most``, else a
    lower bound), in ``unit`` and in percent of the goal: what the bench prints beside each goal."""
    if (value <= goal) if at_most else (value >= goal):
        return f"met ({value:.1f} {unit}, goal {'<=' if at_most else '>='} {goal:g})"
    gap = value - goal if at_most else goal - value
    return f"missed by {gap:.1f} {unit} ({100 * gap / goal:.0f} % of the goal {goal:g})"
