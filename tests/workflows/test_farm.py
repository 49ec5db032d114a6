"""Render-farm determinism: a saved file rendered in a fresh background process (as a Flamenco
worker would, with the add-on enabled) gives the same pixels as the interactive session, at every
frame of an animated edit."""

import os
import subprocess
import sys

import numpy as np
import pytest
from support.farm import keyframed_chrome_spot

bpy = pytest.importorskip("bpy")

from rokeby import envmaps  # noqa: E402

SIZE = 40

WORKER = r"""
import sys
import bpy
import numpy as np
enable, path, out = sys.argv[1] == "1", sys.argv[2], sys.argv[3]
if enable:
    import rokeby
    rokeby.register()  # the add-on enabled on the worker
bpy.ops.wm.open_mainfile(filepath=path)
sc = bpy.context.scene
frames = []
for frame in (1, 20):
    sc.frame_set(frame)
    sc.render.filepath = f"{out}_{frame}.exr"
    bpy.ops.render.render(write_still=True)
"""


def _read(path):
    return envmaps.read_exr(path)[..., :3]


def _worker(enable, path, out):
    env = dict(os.environ)
    res = subprocess.run([sys.executable, "-c", WORKER, "1" if enable else "0", str(path), str(out)], capture_output=True, text=True, timeout=300, env=env)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    return {frame: _read(f"{out}_{frame}.exr") for frame in (1, 20)}


def test_fresh_process_renders_the_same_frames(tmp_path):
    keyframed_chrome_spot(size=SIZE)
    sc = bpy.context.scene
    session = {}
    for frame in (1, 20):
        sc.frame_set(frame)
        sc.render.filepath = str(tmp_path / f"session_{frame}.exr")
        bpy.ops.render.render(write_still=True)
        session[frame] = _read(sc.render.filepath)
    assert np.abs(session[20] - session[1]).max() > 0.1  # the keyframed edit shows
    path = tmp_path / "farm.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))  # saved at frame 20
    worker = _worker(True, path, tmp_path / "worker")
    for frame in (1, 20):
        np.testing.assert_array_equal(worker[frame], session[frame], err_msg=f"frame {frame}")
    # Without the add-on, a worker renders the field as it was saved (frame 20) at every frame:
    # farms must enable it (docs/addon.md says so).
    stale = _worker(False, path, tmp_path / "stale")
    np.testing.assert_array_equal(stale[20], session[20])
    assert np.abs(stale[1] - session[1]).max() > 0.1
