"""What the tests share: paths, deterministic tiny Cycles settings, the shared meshes, and (in the
submodules) the float64 reference, the fresh-bpy-process harness, the GL harness, the fault
injector and the scene set-ups several test files build.

Importable as ``support`` because pyproject.toml puts tests/ on pytest's ``pythonpath``; scripts a
test runs in a fresh process get tests/ on PYTHONPATH from :func:`support.bpy_process.run_check`."""

from __future__ import annotations

import os
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]
ROOT = TESTS.parent
SHARED = Path(os.environ.get("ROKEBY_SHARED", ROOT.parent / "shared"))
MESHES = SHARED / "meshes"
DATA = TESTS / "data"


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
    import pytest

    p = MESHES / name
    if not p.exists():
        pytest.fail(f"shared mesh {p} is missing: set ROKEBY_SHARED to the folder holding meshes/")
    return p


def bench_module(name: str):
    """bench/``name``.py as a module (the compositing tests reuse its synthetic scenes), loaded from
    its file under a name of its own, so nothing is put on ``sys.path`` for it."""
    import importlib.util
    import sys

    key = f"rokeby_bench_{name}"
    if key not in sys.modules:
        spec = importlib.util.spec_from_file_location(key, ROOT / "bench" / f"{name}.py")
        mod = importlib.util.module_from_spec(spec)
        sys.modules[key] = mod
        spec.loader.exec_module(mod)
    return sys.modules[key]
