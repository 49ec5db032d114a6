"""Render-farm job bundles (Open Job Description): the template passes `openjd check`, `openjd run`
renders a keyframed edit's frames bit for bit as the interactive session did, a worker whose
Blender cannot install the add-on fails in the environment, a task without the add-on refuses to
render, and a task killed mid-frame leaves no partial output and its rerun finishes.

The worker's `blender` is FAKE_BLENDER below: a test-only stand-in built on bpy (Blender as a Python
module) that implements exactly the two command forms the template uses — `--command extension
install-file -r REPO -e ZIP` (unpacks the zip's add-on into its own extension folder) and `-b FILE
--python-exit-code 1 --python SCRIPT -- ARGS` (enables the installed add-on, opens FILE, runs
SCRIPT) — so the job's own commands, environment and task script run unchanged."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from support.farm import keyframed_chrome_spot

bpy = pytest.importorskip("bpy")
pytest.importorskip("openjd.cli", reason="openjd-cli is not installed here (requirements-test.txt pins it)")

import rokeby  # noqa: E402
from rokeby import envmaps  # noqa: E402
from rokeby.farm import api as farm  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
SIZE = 40

FAKE_BLENDER = r'''#!{python}
import os, runpy, sys, zipfile
from pathlib import Path
HOME = Path(os.environ["ROKEBY_FAKE_BLENDER_HOME"])
argv = sys.argv[1:]
if argv[:3] == ["--command", "extension", "install-file"]:
    rest = argv[3:]
    repo = rest[rest.index("-r") + 1]
    zpath = rest[-1]
    try:
        with zipfile.ZipFile(zpath) as z:
            manifest = z.read("blender_manifest.toml").decode()
            if 'id = "rokeby"' not in manifest:
                raise ValueError("not the rokeby extension")
            dest = HOME / "extensions" / repo / "rokeby"
            dest.mkdir(parents=True, exist_ok=True)
            z.extractall(dest)
    except Exception as exc:
        print(f"Error: cannot install {{zpath}}: {{exc}}", file=sys.stderr)
        sys.exit(1)
    if "-e" in rest:
        (HOME / "enabled").write_text(str(dest.parent))
    print(f"Installed rokeby into {{repo}}")
    sys.exit(0)
if argv[0] == "-b":
    blend, script = argv[1], argv[argv.index("--python") + 1]
    import bpy, addon_utils
    enabled = HOME / "enabled"
    if enabled.exists():
        sys.path.insert(0, enabled.read_text())
        for name in [m for m in sys.modules if m == "rokeby" or m.startswith("rokeby.")]:
            del sys.modules[name]
        addon_utils.enable("rokeby", default_set=True)
    bpy.ops.wm.open_mainfile(filepath=blend)
    sys.argv = [sys.argv[0]] + argv
    try:
        runpy.run_path(script, run_name="__main__")
    except SystemExit as exc:
        sys.exit(exc.code)
    except BaseException:
        import traceback; traceback.print_exc()
        sys.exit(1)
    sys.exit(0)
print("fake blender: unsupported command line", argv, file=sys.stderr)
sys.exit(2)
'''


def _fake_blender(tmp_path) -> Path:
    exe = tmp_path / "bin" / "blender"
    exe.parent.mkdir(parents=True, exist_ok=True)
    exe.write_text(FAKE_BLENDER.format(python=sys.executable))
    exe.chmod(0o755)
    return exe


def _zip(tmp_path) -> Path:
    """The extension zip as `make dist` builds it (tools/build_extension.py)."""
    sys.path.insert(0, str(ROOT / "tools"))
    try:
        import build_extension as be
    finally:
        sys.path.pop(0)
    wheels = ROOT / "target" / "wheels"
    if not list(wheels.glob("rokeby_native-*.whl")):
        pytest.skip("no rokeby_native wheel in target/wheels (make native builds it)")
    return Path(be.build(ROOT / "addon" / "rokeby", wheels, tmp_path / "dist", ROOT / "shaders"))


def _openjd(bundle, exe, home, *extra, timeout=600):
    values = {p["name"]: p["value"] for p in json.loads((bundle / "parameter_values.yaml").read_text())["parameterValues"]}
    values["BlenderExecutable"] = str(exe)
    env = dict(os.environ, ROKEBY_FAKE_BLENDER_HOME=str(home))
    cmd = [str(Path(sys.executable).parent / "openjd"), "run", str(bundle / "template.yaml"), "--step", "Render",
           "-p", json.dumps(values), *extra]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env)


@pytest.fixture(scope="module")
def shot(tmp_path_factory):
    """A keyframed reflection edit saved to a .blend, and the interactive session's frames 1-4."""
    tmp = tmp_path_factory.mktemp("shot")
    keyframed_chrome_spot()
    sc = bpy.context.scene
    sc.frame_start, sc.frame_end = 1, 20
    session = {}
    for frame in (1, 2, 3, 20):
        sc.frame_set(frame)
        sc.render.filepath = str(tmp / f"session_{frame}.exr")
        bpy.ops.render.render(write_still=True)
        session[frame] = envmaps.read_exr(sc.render.filepath)
    assert np.abs(session[20] - session[1]).max() > 0.1  # the keyframed edit shows
    path = tmp / "shot.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path, session, _zip(tmp)


def test_bundle_passes_openjd_check_and_bad_arguments_are_refused(shot, tmp_path):
    path, _session, z = shot
    bundle = farm.write_render_job(path, tmp_path / "bundle", frames="1-20", chunk=4, zip_path=z)
    assert sorted(p.name for p in bundle.iterdir()) == sorted(["template.yaml", "parameter_values.yaml", z.name])
    r = subprocess.run([str(Path(sys.executable).parent / "openjd"), "check", str(bundle / "template.yaml")],
                       capture_output=True, text=True)
    assert r.returncode == 0 and "passes validation" in r.stdout, r.stdout + r.stderr
    values = {p["name"]: p["value"] for p in json.loads((bundle / "parameter_values.yaml").read_text())["parameterValues"]}
    assert values["RokebyVersion"] == rokeby.__version__ == farm.addon_version()
    for kwargs, word in (({"frames": "9-3"}, "frames"), ({"frames": "x"}, "frames"), ({"frames": "1-4", "chunk": 0}, "chunk"),
                         ({"frames": "1-4", "zip_path": tmp_path / "none.zip"}, "zip_path")):
        with pytest.raises(ValueError, match=word):
            farm.write_render_job(path, tmp_path / "bad", zip_path=kwargs.pop("zip_path", z), **kwargs)
    assert not (tmp_path / "bad").exists()
    cli = subprocess.run([sys.executable, "-m", "rokeby.farm", "render", str(path), str(tmp_path / "cli"), "--frames", "1-2",
                          "--zip", str(z)], capture_output=True, text=True, cwd=ROOT / "addon")
    assert cli.returncode == 0 and (tmp_path / "cli" / "template.yaml").is_file(), cli.stderr
    bad = subprocess.run([sys.executable, "-m", "rokeby.farm", "render", str(path), str(tmp_path / "cli2"), "--frames", "5-1",
                          "--zip", str(z)], capture_output=True, text=True, cwd=ROOT / "addon")
    assert bad.returncode == 2 and bad.stderr.startswith("rokeby.farm: frames:"), bad.stderr


@pytest.mark.slow
def test_openjd_run_renders_the_frames_as_the_session_did(shot, tmp_path):
    path, session, z = shot
    out = tmp_path / "frames"
    bundle = farm.write_render_job(path, tmp_path / "bundle", frames="1-3", chunk=2, zip_path=z, output_dir=out)
    r = _openjd(bundle, _fake_blender(tmp_path), tmp_path / "home")
    assert r.returncode == 0, (r.stdout + r.stderr)[-4000:]
    assert sorted(p.name for p in out.iterdir()) == ["frame_0001.exr", "frame_0002.exr", "frame_0003.exr"]
    for frame in (1, 2, 3):
        np.testing.assert_array_equal(envmaps.read_exr(out / f"frame_{frame:04d}.exr"), session[frame], err_msg=f"frame {frame}")


def test_an_environment_that_cannot_install_the_addon_fails_the_job(shot, tmp_path):
    path, _session, _z = shot
    broken = tmp_path / "rokeby-0.1.0.zip"
    broken.write_text("not a zip")
    out = tmp_path / "frames"
    bundle = farm.write_render_job(path, tmp_path / "bundle", frames="1-1", zip_path=broken, output_dir=out)
    r = _openjd(bundle, _fake_blender(tmp_path), tmp_path / "home")
    assert r.returncode != 0
    text = r.stdout + r.stderr
    assert "cannot install" in text and "RokebyAddon" in text, text[-3000:]
    assert not out.exists() or not list(out.iterdir())


def _task(exe, home, path, out, first, count, end, version=None):
    env = dict(os.environ, ROKEBY_FAKE_BLENDER_HOME=str(home))
    task = Path(farm.__file__).with_name("render_task.py")
    return subprocess.Popen([str(exe), "-b", str(path), "--python-exit-code", "1", "--python", str(task), "--",
                             str(first), str(count), str(end), str(out), version or rokeby.__version__],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)


def test_a_task_refuses_to_render_without_the_addon_or_with_another_version(shot, tmp_path):
    path, _session, z = shot
    exe = _fake_blender(tmp_path)
    out = tmp_path / "frames"
    p = _task(exe, tmp_path / "home", path, out, 1, 1, 1)
    _o, err = p.communicate(timeout=300)
    assert p.returncode == 1 and "add-on is not enabled" in err, err[-2000:]
    env = dict(os.environ, ROKEBY_FAKE_BLENDER_HOME=str(tmp_path / "home"))
    subprocess.run([str(exe), "--command", "extension", "install-file", "-r", "user_default", "-e", str(z)], check=True, env=env)
    p = _task(exe, tmp_path / "home", path, out, 1, 1, 1, version="0.0.9")
    _o, err = p.communicate(timeout=300)
    assert p.returncode == 1 and "job was exported with 0.0.9" in err, err[-2000:]
    assert not out.exists() or not list(out.iterdir())


@pytest.mark.slow
def test_a_killed_task_leaves_no_partial_frame_and_its_rerun_finishes(shot, tmp_path):
    path, session, z = shot
    exe = _fake_blender(tmp_path)
    home = tmp_path / "home"
    env = dict(os.environ, ROKEBY_FAKE_BLENDER_HOME=str(home))
    subprocess.run([str(exe), "--command", "extension", "install-file", "-r", "user_default", "-e", str(z)], check=True, env=env)
    out = tmp_path / "frames"
    p = _task(exe, home, path, out, 1, 3, 3)
    deadline = time.monotonic() + 300
    while not (out / "frame_0001.exr").exists():  # the first frame is whole; the second is rendering
        assert p.poll() is None and time.monotonic() < deadline, p.communicate()[1][-2000:]
        time.sleep(0.05)
    p.send_signal(signal.SIGKILL)
    p.communicate(timeout=60)
    assert [f.name for f in sorted(out.iterdir()) if not f.name.startswith(".")] in (["frame_0001.exr"], ["frame_0001.exr", "frame_0002.exr"])
    p = _task(exe, home, path, out, 1, 3, 3)
    stdout, err = p.communicate(timeout=300)
    assert p.returncode == 0, err[-2000:]
    assert "frame 1: done already, skipped" in stdout
    assert sorted(f.name for f in out.iterdir()) == ["frame_0001.exr", "frame_0002.exr", "frame_0003.exr"]  # no partial left
    for frame in (1, 2, 3):
        np.testing.assert_array_equal(envmaps.read_exr(out / f"frame_{frame:04d}.exr"), session[frame], err_msg=f"frame {frame}")
    shutil.rmtree(out)


def test_export_farm_job_operator_writes_the_bundle_of_the_saved_file(shot, tmp_path):
    path, _session, z = shot
    bpy.ops.wm.open_mainfile(filepath=str(path))
    rokeby.register()
    sc = bpy.context.scene
    assert bpy.ops.rokeby.farm_export.poll()
    r = bpy.ops.rokeby.farm_export(directory=str(tmp_path / "bundle"), frame_start=sc.frame_start, frame_end=sc.frame_end,
                                   chunk=5, zip_path=str(z))
    assert r == {"FINISHED"}
    values = {p["name"]: p["value"] for p in json.loads((tmp_path / "bundle" / "parameter_values.yaml").read_text())["parameterValues"]}
    assert (values["BlendFile"], values["FrameStart"], values["FrameEnd"], values["ChunkSize"]) == (str(path), 1, 20, 5)
    with pytest.raises(RuntimeError, match="frames: the last frame 1 is before the first 5"):
        bpy.ops.rokeby.farm_export(directory=str(tmp_path / "bad"), frame_start=5, frame_end=1, zip_path=str(z))
    assert not (tmp_path / "bad").exists()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    rokeby.register()
    assert not bpy.ops.rokeby.farm_export.poll()  # never saved
