"""A render-farm job bundle run by `openjd run` with Debian's real Blender 4.3 as the worker (in the
window leg's root, background mode): the job environment installs the extension zip with
`blender --command extension install-file -r user_default -e ZIP` (the real command line, not a
stand-in), and the tasks render a keyframed edit whose frames differ as the edit moves. The
bit-for-bit comparison with an interactive session is tests/workflows/test_farm_jobs.py's (with
bpy); here the point is that the commands the template runs are those a real Blender accepts."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from harness import GUIROOT, REPO

SHOT = r"""
import sys
sys.path[:0] = [sys.argv[-2] + "/tests", sys.argv[-2] + "/blend_fixtures"]
import bpy
from support.farm import keyframed_chrome_spot
keyframed_chrome_spot(file_format="PNG", denoise=False)
bpy.ops.wm.save_as_mainfile(filepath=sys.argv[-1])
"""

def test_openjd_runs_the_render_job_with_debian_blender(dist_zip):
    pytest.importorskip("openjd.cli", reason="openjd-cli is not installed here (requirements-test.txt pins it)")
    from rokeby.farm import api as farm

    work = REPO / "target" / "gui" / "farm_job"  # under the project: bound inside the root at the same path
    shutil.rmtree(work, ignore_errors=True)
    (work / "tmp").mkdir(parents=True)
    blend = work / "shot.blend"
    made = subprocess.run([sys.executable, "-c", SHOT, str(REPO), str(blend)], capture_output=True, text=True, timeout=300)
    assert made.returncode == 0 and blend.is_file(), made.stderr[-2000:]
    out = work / "out"
    bundle = farm.write_render_job(blend, work / "bundle", frames="1-20", chunk=19, zip_path=dist_zip, output_dir=out)
    blender = work / "blender"
    # A fresh user configuration inside the root (tools/guiroot sets HOME=/root otherwise).
    blender.write_text(f"#!/bin/bash\nexec {GUIROOT} bash -c 'export HOME={work}/home; mkdir -p \"$HOME\"; exec blender \"$@\"' blender \"$@\"\n")
    blender.chmod(0o755)
    values = {p["name"]: p["value"] for p in json.loads((bundle / "parameter_values.yaml").read_text())["parameterValues"]}
    values["BlenderExecutable"] = str(blender)
    # The session's files (the embedded task script) must be visible inside the root: under the project.
    env = dict(os.environ, TMPDIR=str(work / "tmp"))
    r = subprocess.run([str(Path(sys.executable).parent / "openjd"), "run", str(bundle / "template.yaml"), "--step", "Render",
                        "-p", json.dumps(values)], capture_output=True, text=True, timeout=900, env=env)
    log = r.stdout + r.stderr
    (work / "openjd.log").write_text(log)
    assert r.returncode == 0, log[-4000:]
    assert 'Installed "rokeby"' in log, log[-4000:]  # the real `extension install-file` ran in the environment
    frames = sorted(p.name for p in out.iterdir())
    assert frames == [f"frame_{f:04d}.png" for f in range(1, 21)], frames
    assert (out / "frame_0001.png").read_bytes() != (out / "frame_0020.png").read_bytes()  # the keyframed edit moves
