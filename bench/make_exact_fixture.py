"""Regenerate tests/data/spot_exact_geodesics.npz: exact polyhedral geodesic distances (pygeodesic's
MMP) on spot.obj from three source vertices, the ground truth of tests/reflection/test_geodesic.py.

Runs in .venv-peers (pygeodesic needs numpy >= 2; the test environment has bpy's numpy < 2):

    make .venv-peers/.deps && .venv-peers/bin/python bench/make_exact_fixture.py
"""

import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "addon"))
from rokeby.core.meshio import load_obj  # noqa: E402

import pygeodesic.geodesic as geo  # noqa: E402

SHARED = Path(os.environ.get("ROKEBY_SHARED", ROOT.parent / "shared"))
v, f = load_obj(SHARED / "meshes" / "spot.obj")
sources = np.array([int(f[len(f) * k // 4, 0]) for k in (1, 2, 3)])
alg = geo.PyGeodesicAlgorithmExact(v.astype(np.float64), f.astype(np.int32))
d = np.array([alg.geodesicDistances(np.array([s], dtype=np.int32), None)[0] for s in sources])
out = ROOT / "tests" / "data" / "spot_exact_geodesics.npz"
np.savez_compressed(out, sources=sources, distances=d.astype(np.float64), num_vertices=len(v))
print(f"wrote {out}: sources {sources.tolist()}, max distance {d.max():.4f}")
