"""The checks that need Blender's GPU context run in a fresh bpy process (background mode makes the
context with one tiny EEVEE render, and a process keeps it): the test side runs a ``*_check.py``
script and reads the one line ``RESULT {json}`` it prints (:func:`run_check`); the script side
makes the context (:func:`gpu_context`) and draws offscreen (:func:`offscreen_pixels`)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np

from support import TESTS


def run_check(script: str, timeout: int = 600, args=()) -> dict:
    """Runs tests/``script`` (a path below tests/, e.g. ``"appearance/appearance_preview_check.py"``)
    with this Python, tests/ on its PYTHONPATH (it imports ``support``), and returns its RESULT
    (fails the test without one, skips it when the result is ``{"skip": reason}``)."""
    import pytest

    path = TESTS / script
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (str(TESTS), os.environ.get("PYTHONPATH")) if p)}
    r = subprocess.run([sys.executable, str(path), *map(str, args)], capture_output=True, text=True, timeout=timeout,
                       env=env)
    line = next((ln for ln in r.stdout.splitlines() if ln.startswith("RESULT ")), None)
    if line is None:
        pytest.fail(f"no result from {script} (rc {r.returncode}): {r.stdout[-1500:]} {r.stderr[-2500:]}")
    out = json.loads(line[len("RESULT "):])
    if isinstance(out, dict) and "skip" in out:
        pytest.skip(out["skip"])
    return out


def gpu_context(scene) -> None:
    """Blender's GPU context in background mode: one 8×8 render, with ``compat.eevee_engine()``, of an
    empty scene made for it (then removed). The scene is empty so that EEVEE compiles no material of
    the test's own: on llvmpipe that compilation took minutes, and the context is all a check needs.
    ``scene`` (the check's own) is neither rendered nor changed."""
    import bpy

    from rokeby.blender import compat

    tmp = bpy.data.scenes.new("gpu context")
    try:
        cam = bpy.data.objects.new("gpu context camera", bpy.data.cameras.new("gpu context camera"))
        tmp.collection.objects.link(cam)
        tmp.camera = cam
        tmp.render.engine = compat.eevee_engine()
        tmp.render.resolution_x = tmp.render.resolution_y = 8
        bpy.ops.render.render(scene=tmp.name)
    finally:
        cams = [o for o in tmp.collection.objects if o.type == "CAMERA"]
        bpy.data.scenes.remove(tmp)
        for o in cams:
            data = o.data
            bpy.data.objects.remove(o)
            bpy.data.cameras.remove(data)


def offscreen_pixels(draw, width: int, height: int) -> np.ndarray:
    """(height, width, 4) float32 of what ``draw()`` draws into a cleared RGBA32F offscreen buffer
    (depth cleared to 1); row 0 is the bottom, as read_color gives it."""
    import gpu

    off = gpu.types.GPUOffScreen(width, height, format="RGBA32F")
    try:
        with off.bind():
            fb = gpu.state.active_framebuffer_get()
            fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
            draw()
            return np.array(fb.read_color(0, 0, width, height, 4, 0, "FLOAT").to_list(), np.float32).reshape(height, width, 4)
    finally:
        off.free()
