import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import settings

ROOT = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("ROKEBY_SHARED", ROOT.parent / "shared"))
MESHES = SHARED / "meshes"

# Seeded and bounded: the same examples on every run, no database written into the checkout.
settings.register_profile("rokeby", derandomize=True, database=None, deadline=None, max_examples=200)
settings.load_profile("rokeby")


def cycles(sc, size: int, samples: int, seed: int = 1):
    """Deterministic tiny Cycles renders for the pixel tests: CPU, no denoising, a fixed seed,
    a square image of ``size`` pixels."""
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.cycles.samples = samples
    sc.cycles.use_denoising = False
    sc.cycles.seed = seed
    sc.render.resolution_x = sc.render.resolution_y = size
    sc.render.resolution_percentage = 100
    return sc


def mesh_path(name: str) -> Path:
    p = MESHES / name
    if not p.exists():
        pytest.fail(f"shared mesh {p} is missing: set ROKEBY_SHARED to the folder holding meshes/")
    return p


@pytest.fixture(scope="session")
def spot():
    from rokeby.meshio import load_obj, vertex_normals

    v, f = load_obj(mesh_path("spot.obj"))
    return v, f, vertex_normals(v, f)


@pytest.fixture
def rng():
    return np.random.default_rng(20091001)
