"""Render-farm job bundles run by `openjd run` with Debian's real Blender 4.3 as the worker (in the
window leg's root, background mode): the job environment installs the extension zip with
`blender --command extension install-file -r user_default -e ZIP` (the real command line, not a
stand-in) and checks it is enabled; the render job's tasks render a keyframed edit whose frames
differ as the edit moves, and the recompositing job's tasks run `python -m rokeby.composite` inside
that Blender (its Python and numpy, the wheel the zip installed) with the pixels of the command run
here, to float32 rounding.
The bit-for-bit comparison with an interactive session is tests/workflows/test_farm_jobs.py's (with
bpy); here the point is that the commands the templates run are those a real Blender accepts."""

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


def run_openjd(work: Path, bundle: Path, step: str) -> str:
    """``openjd run`` of ``bundle``'s ``step`` with Debian's Blender (a fresh user configuration
    inside the root; tools/guiroot sets HOME=/root otherwise) as the worker; asserts it succeeded
    and returns its log (also written to ``work``/openjd.log)."""
    blender = work / "blender"
    blender.write_text(f"#!/bin/bash\nexec {GUIROOT} bash -c 'export HOME={work}/home; mkdir -p \"$HOME\"; exec blender \"$@\"' blender \"$@\"\n")
    blender.chmod(0o755)
    values = {p["name"]: p["value"] for p in json.loads((bundle / "parameter_values.yaml").read_text())["parameterValues"]}
    values["BlenderExecutable"] = str(blender)
    # The session's files (the embedded task script) must be visible inside the root: under the project.
    env = dict(os.environ, TMPDIR=str(work / "tmp"))
    r = subprocess.run([str(Path(sys.executable).parent / "openjd"), "run", str(bundle / "template.yaml"), "--step", step,
                        "-p", json.dumps(values)], capture_output=True, text=True, timeout=900, env=env)
    log = r.stdout + r.stderr
    (work / "openjd.log").write_text(log)
    assert r.returncode == 0, log[-4000:]
    return log


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
    log = run_openjd(work, bundle, "Render")
    assert 'Installed "rokeby"' in log, log[-4000:]  # the real `extension install-file` ran in the environment
    frames = sorted(p.name for p in out.iterdir())
    assert frames == [f"frame_{f:04d}.png" for f in range(1, 21)], frames
    assert (out / "frame_0001.png").read_bytes() != (out / "frame_0020.png").read_bytes()  # the keyframed edit moves


FRAMES = r"""
import sys
sys.path[:0] = [sys.argv[-2] + "/tests"]
from support.compositing import pass_scene
from rokeby import compositing as C
sc = pass_scene()
sc.render.resolution_x, sc.render.resolution_y, sc.cycles.samples = 32, 24, 4
for k in (1, 2, 3):
    sc.camera.location.x = 0.3 + 0.08 * k
    C.render_passes(sc, f"{sys.argv[-1]}/shot_{k:04d}.exr")
"""


def test_openjd_runs_the_recompositing_job_with_debian_blender(dist_zip):
    pytest.importorskip("openjd.cli", reason="openjd-cli is not installed here (requirements-test.txt pins it)")
    import numpy as np

    from rokeby import envmaps
    from rokeby.farm import api as farm

    work = REPO / "target" / "gui" / "farm_recomposite"
    shutil.rmtree(work, ignore_errors=True)
    (work / "tmp").mkdir(parents=True)
    frames = work / "frames"
    frames.mkdir()
    made = subprocess.run([sys.executable, "-c", FRAMES, str(REPO), str(frames)], capture_output=True, text=True, timeout=600)
    assert made.returncode == 0 and len(list(frames.glob("*.exr"))) == 3, made.stderr[-2000:]
    edit = ["--emboss", "0.4", "--kr", "0.8"]
    ref = work / "reference"
    r = subprocess.run([sys.executable, "-m", "rokeby.composite", "--sequence", str(frames), str(ref), "--pattern", "shot_####.exr", *edit],
                       capture_output=True, text=True, cwd=REPO / "addon", timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    out = work / "out"
    bundle = farm.write_recomposite_job(frames, out, work / "bundle", pattern="shot_####.exr", edit_options=edit, chunk=2,
                                        zip_path=dist_zip)
    log = run_openjd(work, bundle, "Recomposite")
    assert "is enabled in Blender 4.3" in log, log[-4000:]  # the check environment ran in the real Blender
    assert sorted(p.name for p in out.iterdir()) == [f"shot_{k:04d}.exr" for k in (1, 2, 3)]
    # Debian's Blender runs the reconstruction with Debian's numpy (2.2; here 1.26): the same pixels
    # to float32 rounding (measured: at most 2e-6 apart). Bit for bit with one environment on both
    # sides: tests/workflows/test_farm_jobs.py.
    for k in (1, 2, 3):
        name = f"shot_{k:04d}.exr"
        np.testing.assert_allclose(envmaps.read_exr(out / name), envmaps.read_exr(ref / name), rtol=1e-5, atol=1e-5, err_msg=name)
