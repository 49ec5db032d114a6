"""Render-farm job bundles (Open Job Description): every template passes `openjd check`; `openjd run`
renders a keyframed edit's frames bit for bit as the interactive session did, and recomposites an
EXR sequence bit for bit as the single-process `python -m rokeby.composite --sequence` does; a worker
whose Blender cannot install or enable the add-on fails in the job's environment; a task without
the add-on, or with another version than the file was saved with (the scene marker), refuses to
render; a task killed or cancelled mid-frame leaves no partial output and its rerun finishes.

The worker's `blender` is tests/support/fake_blender.py: a TEST-ONLY stand-in built on bpy that
implements exactly the command forms the templates use (`--command extension install-file -r REPO
-e ZIP`, `-b [FILE] --python-exit-code 1 --python SCRIPT -- ARGS`), so the job's own commands,
environments and worker script run unchanged. tests/gui/test_farm_job.py runs a render job with
Debian's real Blender in the window leg."""

import json
import os
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest
from support import fake_blender
from support.compositing import pass_scene
from support.farm import keyframed_chrome_spot

bpy = pytest.importorskip("bpy")
pytest.importorskip("openjd.cli", reason="openjd-cli is not installed here (requirements-test.txt pins it)")

import rokeby  # noqa: E402
from rokeby import api, envmaps  # noqa: E402
from rokeby import compositing as C  # noqa: E402
from rokeby.core import schema  # noqa: E402
from rokeby.farm import api as farm  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
OPENJD = str(Path(sys.executable).parent / "openjd")
PATTERN = "shot_####.exr"
EDIT = ["--emboss", "0.4", "--kd", "0.9"]


def _zip(tmp_path, version=None) -> Path:
    """The extension zip as `make dist` builds it (tools/build_extension.py); with ``version``, the
    same add-on relabelled as that version (manifest and ``rokeby.__version__``)."""
    sys.path.insert(0, str(ROOT / "tools"))
    try:
        import build_extension as be
    finally:
        sys.path.pop(0)
    wheels = ROOT / "target" / "wheels"
    if not list(wheels.glob("rokeby_native-*.whl")):
        pytest.skip("no rokeby_native wheel in target/wheels (make native builds it)")
    z = Path(be.build(ROOT / "addon" / "rokeby", wheels, tmp_path / "dist", ROOT / "shaders"))
    if version is None:
        return z
    other = tmp_path / "other" / f"rokeby-{version}.zip"
    other.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(z) as src, zipfile.ZipFile(other, "w", zipfile.ZIP_DEFLATED) as dst:
        for info in src.infolist():
            data = src.read(info)
            if info.filename in ("blender_manifest.toml", "__init__.py"):
                text = data.decode()
                assert rokeby.__version__ in text
                data = text.replace(f'"{rokeby.__version__}"', f'"{version}"').encode()
            dst.writestr(info, data)
    return other


def _values(bundle) -> dict:
    return {p["name"]: p["value"] for p in json.loads((bundle / "parameter_values.yaml").read_text())["parameterValues"]}


def _openjd(bundle, step, tmp_path, *, popen=False, **override):
    values = {**_values(bundle), "BlenderExecutable": str(fake_blender.write(tmp_path / "bin")), **override}
    env = dict(os.environ, ROKEBY_FAKE_BLENDER_HOME=str(tmp_path / "home"))
    cmd = [OPENJD, "run", str(bundle / "template.yaml"), "--step", step, "-p", json.dumps(values)]
    if popen:
        return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    return subprocess.run(cmd, capture_output=True, text=True, timeout=900, env=env)


def _install(tmp_path, z):
    env = dict(os.environ, ROKEBY_FAKE_BLENDER_HOME=str(tmp_path / "home"))
    exe = fake_blender.write(tmp_path / "bin")
    subprocess.run([str(exe), "--command", "extension", "install-file", "-r", "user_default", "-e", str(z)], check=True, env=env,
                   capture_output=True)
    return exe, env


def _worker(tmp_path, z, *args, blend=None):
    """The job's worker script in the stand-in Blender (the zip installed first), as a task runs it."""
    exe, env = _install(tmp_path, z)
    worker = Path(farm.__file__).with_name("worker.py")
    cmd = [str(exe), "-b", *([str(blend)] if blend else []), "--python-exit-code", "1", "--python", str(worker), "--", *map(str, args)]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)


def _names(folder) -> list:
    return sorted(p.name for p in Path(folder).iterdir()) if Path(folder).exists() else []


def _assert_same_frames(out, ref):
    """``out`` holds the frames of ``ref``, bit for bit."""
    assert _names(out) == _names(ref)
    for name in _names(ref):
        np.testing.assert_array_equal(envmaps.read_exr(out / name), envmaps.read_exr(ref / name), err_msg=name)


@pytest.fixture(scope="module")
def shot(tmp_path_factory):
    """A keyframed reflection edit saved to a .blend, and the interactive session's frames 1-4 and 20."""
    tmp = tmp_path_factory.mktemp("shot")
    keyframed_chrome_spot()
    sc = bpy.context.scene
    sc.frame_start, sc.frame_end = 1, 20
    session = {}
    for frame in (1, 2, 3, 4, 20):
        sc.frame_set(frame)
        sc.render.filepath = str(tmp / f"session_{frame}.exr")
        bpy.ops.render.render(write_still=True)
        session[frame] = envmaps.read_exr(sc.render.filepath)
    assert np.abs(session[20] - session[1]).max() > 0.1  # the keyframed edit shows
    path = tmp / "shot.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path, session, _zip(tmp)


@pytest.fixture(scope="module")
def sequence(tmp_path_factory):
    """Six multilayer EXR frames with the compositing passes (the camera moving), and the
    single-process command's recomposited frames."""
    tmp = tmp_path_factory.mktemp("sequence")
    sc = pass_scene()
    sc.render.resolution_x, sc.render.resolution_y, sc.cycles.samples = 32, 24, 4
    frames = tmp / "frames"
    frames.mkdir()
    for k in range(1, 7):
        sc.camera.location.x = 0.3 + 0.08 * k
        C.render_passes(sc, str(frames / f"shot_{k:04d}.exr"))
    (frames / "notes.txt").write_text("not a frame")
    ref = tmp / "reference"
    r = subprocess.run([sys.executable, "-m", "rokeby.composite", "--sequence", str(frames), str(ref), "--pattern", PATTERN, *EDIT],
                       capture_output=True, text=True, cwd=ROOT / "addon", timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    assert _names(ref) == [f"shot_{k:04d}.exr" for k in range(1, 7)]
    a, b = envmaps.read_exr(ref / "shot_0001.exr"), envmaps.read_exr(ref / "shot_0006.exr")
    assert np.abs(a - b).max() > 0.05  # the frames differ
    return frames, ref, _zip(tmp)


# --- the bundles ---------------------------------------------------------------------------------


def _check(bundle):
    r = subprocess.run([OPENJD, "check", str(bundle / "template.yaml")], capture_output=True, text=True)
    assert r.returncode == 0 and "passes validation" in r.stdout, r.stdout + r.stderr


def test_bundles_pass_openjd_check_and_bad_arguments_are_refused(shot, sequence, tmp_path):
    path, _session, z = shot
    bundle = farm.write_render_job(path, tmp_path / "bundle", frames="1-20", chunk=4, zip_path=z)
    assert _names(bundle) == sorted(["template.yaml", "parameter_values.yaml", z.name])
    _check(bundle)
    values = _values(bundle)
    assert values["RokebyVersion"] == rokeby.__version__ == farm.addon_version() == farm.zip_version(z)
    template = json.loads((bundle / "template.yaml").read_text())
    assert [e["name"] for e in template["jobEnvironments"]] == ["RokebyAddon", "RokebyAddonCheck"]
    for kwargs, word in (({"frames": "9-3"}, "frames"), ({"frames": "x"}, "frames"), ({"frames": "1-4", "chunk": 0}, "chunk"),
                         ({"frames": "1-4", "zip_path": tmp_path / "none.zip"}, "zip_path"),
                         ({"frames": "1-4", "zip_path": path}, "not a Blender extension zip"),
                         ({"frames": "1-4", "saved_with": "0.0.9"}, "the file was saved with Rokeby 0.0.9")):
        with pytest.raises(ValueError, match=word):
            farm.write_render_job(path, tmp_path / "bad", zip_path=kwargs.pop("zip_path", z), **kwargs)
    assert not (tmp_path / "bad").exists()
    # Without a zip, from the checkout: the zip `make dist` builds, the same bytes.
    built = farm.write_render_job(path, tmp_path / "built", frames="1-2")
    assert (built / z.name).read_bytes() == z.read_bytes()

    frames, _ref, _z = sequence
    rec = api.write_recomposite_job(frames, tmp_path / "out", tmp_path / "rbundle", pattern=PATTERN, edit_options=EDIT, chunk=4, zip_path=z)
    _check(rec)
    values = _values(rec)
    assert (values["FrameStart"], values["FrameEnd"], values["FramePattern"]) == (1, 6, PATTERN)
    args = json.loads((rec / "template.yaml").read_text())["steps"][0]["script"]["actions"]["onRun"]["args"]
    assert args[-len(EDIT):] == EDIT
    height = tmp_path / "height.npy"
    np.save(height, np.zeros((24, 32), np.float32))
    bumped = api.write_recomposite_job(frames, tmp_path / "out", tmp_path / "bbundle", pattern=PATTERN,
                                       edit_options=["--bump", str(height)], zip_path=z)
    _check(bumped)
    assert _values(bumped)["BumpImage"] == str(height)
    for kwargs, word in (({"edit_options": ["--emboss", "x"]}, "--emboss: invalid float"),
                         ({"edit_options": ["--frame", "2"]}, "--frame is not an edit option"),
                         ({"edit_options": ["--kd", "nan"]}, "k_d: must be finite"),
                         ({"edit_options": ["--bump", str(tmp_path / "none.npy")]}, "--bump: no such file"),
                         ({"pattern": "none_*.exr"}, "no frames matching"),
                         ({"chunk": 0}, "chunk")):
        with pytest.raises(ValueError, match=word):
            api.write_recomposite_job(frames, tmp_path / "out", tmp_path / "bad", **{"pattern": PATTERN, "zip_path": z, **kwargs})
    with pytest.raises(ValueError, match="must differ"):
        api.write_recomposite_job(frames, frames, tmp_path / "bad", pattern=PATTERN, zip_path=z)
    assert not (tmp_path / "bad").exists()


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "rokeby.farm", *map(str, args)], capture_output=True, text=True, cwd=ROOT / "addon",
                          timeout=300)


def test_command_line_writes_both_bundles(shot, sequence, tmp_path):
    path, _session, z = shot
    frames, _ref, _z = sequence
    r = _cli("render", path, tmp_path / "cli", "--frames", "1-2", "--zip", z)
    assert r.returncode == 0 and r.stdout.strip() == str(tmp_path / "cli"), r.stderr
    _check(tmp_path / "cli")
    r = _cli("recomposite", frames, tmp_path / "out", tmp_path / "rcli", "--pattern", PATTERN, "--chunk", "3", "--zip", z, *EDIT)
    assert r.returncode == 0, r.stderr
    _check(tmp_path / "rcli")
    assert _values(tmp_path / "rcli")["ChunkSize"] == 3
    for args, msg in ((("render", path, tmp_path / "x", "--frames", "5-1", "--zip", z), "rokeby.farm: frames:"),
                      (("render", path, tmp_path / "x", "--frames", "1-2", "--emboss", "1"), "unrecognized arguments: --emboss"),
                      (("recomposite", frames, tmp_path / "o", tmp_path / "x", "--pattern", PATTERN, "--zip", z, "--emboss", "big"),
                       "rokeby.farm: edit options: argument --emboss: invalid float value"),
                      (("recomposite", frames, tmp_path / "o", tmp_path / "x", "--zip", z, "--nosuch"), "unrecognized arguments: --nosuch")):
        r = _cli(*args)
        assert r.returncode == 2 and msg in r.stderr and "Traceback" not in r.stderr, (args, r.stderr)
    assert not (tmp_path / "x").exists()


# --- running them ----------------------------------------------------------------------------------


@pytest.mark.slow
def test_openjd_run_renders_the_frames_as_the_session_did(shot, tmp_path):
    path, session, z = shot
    out = tmp_path / "frames"
    bundle = farm.write_render_job(path, tmp_path / "bundle", frames="1-4", chunk=3, zip_path=z, output_dir=out)
    r = _openjd(bundle, "Render", tmp_path)
    log = r.stdout + r.stderr
    assert r.returncode == 0, log[-4000:]
    assert f"Rokeby {rokeby.__version__} is enabled" in log  # the RokebyAddonCheck environment ran
    assert _names(out) == [f"frame_{f:04d}.exr" for f in (1, 2, 3, 4)]
    for frame in (1, 2, 3, 4):
        np.testing.assert_array_equal(envmaps.read_exr(out / f"frame_{frame:04d}.exr"), session[frame], err_msg=f"frame {frame}")


@pytest.mark.slow
def test_openjd_run_recomposites_the_sequence_as_the_single_process_command(sequence, tmp_path):
    frames, ref, z = sequence
    out = tmp_path / "out"
    bundle = api.write_recomposite_job(frames, out, tmp_path / "bundle", pattern=PATTERN, edit_options=EDIT, chunk=4, zip_path=z)
    r = _openjd(bundle, "Recomposite", tmp_path)
    assert r.returncode == 0, (r.stdout + r.stderr)[-4000:]
    _assert_same_frames(out, ref)


def test_an_environment_that_cannot_install_or_enable_the_addon_fails_the_job(shot, tmp_path):
    path, _session, z = shot
    out = tmp_path / "frames"
    bundle = farm.write_render_job(path, tmp_path / "bundle", frames="1-1", zip_path=z, output_dir=out)
    # The zip the worker got is damaged: the install fails, in the first environment.
    broken = tmp_path / "damaged" / z.name
    broken.parent.mkdir()
    broken.write_bytes(z.read_bytes()[: len(z.read_bytes()) // 2])
    r = _openjd(bundle, "Render", tmp_path / "a", ExtensionZip=str(broken))
    text = r.stdout + r.stderr
    assert r.returncode != 0 and "cannot install" in text and "RokebyAddon" in text, text[-3000:]
    assert "rokeby.farm: frame" not in text and "RokebyAddonCheck" not in text  # nothing ran after it
    # It installs, but the add-on fails to enable (here: an import error, as a wheel for another
    # platform would give): the check environment says so, and no task runs.
    unloadable = tmp_path / "unloadable" / z.name
    unloadable.parent.mkdir()
    with zipfile.ZipFile(z) as src, zipfile.ZipFile(unloadable, "w") as dst:
        for info in src.infolist():
            data = src.read(info)
            if info.filename == "__init__.py":
                data = b"raise ImportError('rokeby_native: no wheel for this platform')\n" + data
            dst.writestr(info, data)
    r = _openjd(bundle, "Render", tmp_path / "b", ExtensionZip=str(unloadable))
    text = r.stdout + r.stderr
    assert r.returncode != 0 and "RokebyAddonCheck" in text and "the Rokeby add-on is not enabled in this Blender" in text, text[-3000:]
    # The job asks for another version than the zip installs.
    r = _openjd(bundle, "Render", tmp_path / "c", RokebyVersion="0.0.9")
    text = r.stdout + r.stderr
    assert r.returncode != 0 and f"is version {rokeby.__version__}; the job was exported with 0.0.9" in text, text[-3000:]
    assert not _names(out)


def test_the_saved_file_records_its_rokeby_and_a_task_refuses_another(shot, tmp_path):
    path, _session, z = shot
    bpy.ops.wm.open_mainfile(filepath=str(path))
    assert bpy.context.scene[schema.SCENE_SAVED_WITH_KEY] == rokeby.__version__  # the save_pre marker
    out = tmp_path / "frames"
    # Without the add-on at all: the task refuses.
    env = dict(os.environ, ROKEBY_FAKE_BLENDER_HOME=str(tmp_path / "bare"))
    exe = fake_blender.write(tmp_path / "bare-bin")
    worker = Path(farm.__file__).with_name("worker.py")
    r = subprocess.run([str(exe), "-b", str(path), "--python-exit-code", "1", "--python", str(worker), "--", "render", "1", "1", "1",
                        str(out), rokeby.__version__, schema.SCENE_SAVED_WITH_KEY], capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 1 and "the Rokeby add-on is not enabled" in r.stderr, r.stderr[-2000:]
    # Another version (the job exported with its zip): the file's marker names the one it needs.
    other = _zip(tmp_path, version="0.0.9")
    with pytest.raises(ValueError, match="the file was saved with Rokeby " + rokeby.__version__):
        farm.write_render_job(path, tmp_path / "bundle", frames="1-1", zip_path=other, saved_with=rokeby.__version__)
    p = _worker(tmp_path, other, "render", 1, 1, 1, out, "0.0.9", schema.SCENE_SAVED_WITH_KEY, blend=path)
    _o, err = p.communicate(timeout=300)
    assert p.returncode == 1 and f"the file was saved with Rokeby {rokeby.__version__}, the add-on enabled here is 0.0.9" in err, err[-2000:]
    assert not _names(out)
    # A file without render-time edits carries no marker (and one that had it loses it).
    bpy.ops.wm.read_factory_settings(use_empty=True)
    rokeby.register()
    bpy.context.scene[schema.SCENE_SAVED_WITH_KEY] = "0.0.1"
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "plain.blend"))
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "plain.blend"))
    assert schema.SCENE_SAVED_WITH_KEY not in bpy.context.scene


@pytest.mark.slow
def test_a_killed_render_task_leaves_no_partial_frame_and_its_rerun_finishes(shot, tmp_path):
    path, session, z = shot
    out = tmp_path / "frames"
    args = ("render", 1, 3, 3, out, rokeby.__version__, schema.SCENE_SAVED_WITH_KEY)
    p = _worker(tmp_path, z, *args, blend=path)
    deadline = time.monotonic() + 300
    while not (out / "frame_0001.exr").exists():  # the first frame is whole; the second is rendering
        assert p.poll() is None and time.monotonic() < deadline, p.communicate()[1][-2000:]
        time.sleep(0.05)
    p.send_signal(signal.SIGKILL)
    p.communicate(timeout=60)
    assert [n for n in _names(out) if not n.startswith(".")] in (["frame_0001.exr"], ["frame_0001.exr", "frame_0002.exr"])
    p = _worker(tmp_path, z, *args, blend=path)
    stdout, err = p.communicate(timeout=300)
    assert p.returncode == 0, err[-2000:]
    assert "frame 1: done already, skipped" in stdout
    assert _names(out) == ["frame_0001.exr", "frame_0002.exr", "frame_0003.exr"]  # no partial left
    for frame in (1, 2, 3):
        np.testing.assert_array_equal(envmaps.read_exr(out / f"frame_{frame:04d}.exr"), session[frame], err_msg=f"frame {frame}")


@pytest.mark.slow
def test_a_cancelled_recompositing_job_leaves_no_partial_frame_and_its_rerun_finishes(sequence, tmp_path):
    """openjd run is cancelled (SIGINT, as Ctrl-C or a scheduler's cancel) while its task works on
    the sequence: the task gets SIGTERM (NOTIFY_THEN_TERMINATE) and stops without a partial frame;
    a killed task's temporary file is removed by the rerun, which finishes the frames."""
    frames, ref, z = sequence
    out = tmp_path / "out"
    bundle = api.write_recomposite_job(frames, out, tmp_path / "bundle", pattern=PATTERN, edit_options=EDIT, chunk=6, zip_path=z)
    p = _openjd(bundle, "Recomposite", tmp_path, popen=True)
    deadline = time.monotonic() + 600
    while not (out / "shot_0001.exr").exists():
        assert p.poll() is None and time.monotonic() < deadline, p.communicate()[0][-3000:]
        time.sleep(0.02)
    p.send_signal(signal.SIGINT)
    log = p.communicate(timeout=300)[0]
    assert p.returncode != 0, log[-3000:]
    assert "Interruption signal" in log and "rokeby.farm: cancelled" in log, log[-3000:]  # the task stopped itself
    done = _names(out)
    assert done and all(n.startswith("shot_") for n in done) and len(done) < 6, (done, log[-3000:])  # whole frames only
    # What SIGKILL in the middle of writing a frame leaves: a temporary file beside it.
    missing = sorted(set(_names(ref)) - set(done))[0]
    stale = out / f".{missing}.partial-99999.exr"
    stale.write_bytes(b"half a frame")
    r = _openjd(bundle, "Recomposite", tmp_path)
    assert r.returncode == 0, (r.stdout + r.stderr)[-3000:]
    _assert_same_frames(out, ref)


# --- the operators -------------------------------------------------------------------------------


def test_export_farm_job_operator_writes_the_bundle_of_the_saved_file(shot, tmp_path):
    path, _session, z = shot
    bpy.ops.wm.open_mainfile(filepath=str(path))
    rokeby.register()
    sc = bpy.context.scene
    assert bpy.ops.rokeby.farm_export.poll()
    r = bpy.ops.rokeby.farm_export(directory=str(tmp_path / "bundle"), frame_start=sc.frame_start, frame_end=sc.frame_end,
                                   chunk=5, zip_path=str(z))
    assert r == {"FINISHED"}
    values = _values(tmp_path / "bundle")
    assert (values["BlendFile"], values["FrameStart"], values["FrameEnd"], values["ChunkSize"]) == (str(path), 1, 20, 5)
    with pytest.raises(RuntimeError, match="frames: the last frame 1 is before the first 5"):
        bpy.ops.rokeby.farm_export(directory=str(tmp_path / "bad"), frame_start=5, frame_end=1, zip_path=str(z))
    with pytest.raises(RuntimeError, match="the file was saved with Rokeby"):
        bpy.ops.rokeby.farm_export(directory=str(tmp_path / "bad"), frame_start=1, frame_end=2, zip_path=str(_zip(tmp_path, "0.0.9")))
    assert not (tmp_path / "bad").exists()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    rokeby.register()
    assert not bpy.ops.rokeby.farm_export.poll()  # never saved


def test_export_recompositing_farm_job_is_filled_in_from_the_recomposited_image(sequence, tmp_path):
    frames, _ref, z = sequence
    bpy.ops.wm.read_factory_settings(use_empty=True)
    rokeby.register()
    assert bpy.ops.rokeby.composite_edit(filepath=str(frames / "shot_0003.exr"), edit="SMOOTH", amount=2.5, k_r=0.75) == {"FINISHED"}
    r = bpy.ops.rokeby.farm_export_recomposite(directory=str(tmp_path / "bundle"), chunk=2, zip_path=str(z))
    assert r == {"FINISHED"}
    values = _values(tmp_path / "bundle")
    assert (values["InputDir"], values["FramePattern"], values["FrameEnd"], values["ChunkSize"]) == (str(frames), PATTERN, 6, 2)
    assert values["OutputDir"] == str(frames / "recomposited")
    args = json.loads((tmp_path / "bundle" / "template.yaml").read_text())["steps"][0]["script"]["actions"]["onRun"]["args"]
    assert args[args.index("{{Param.RokebyVersion}}") + 1:] == ["--smooth", "2.5", "--kr", "0.75"]
    # The one-knob edit as options gives the operator's pixels.
    one = tmp_path / "one.exr"
    cmd = [sys.executable, "-m", "rokeby.composite", str(frames / "shot_0003.exr"), str(one), "--smooth", "2.5", "--kr", "0.75"]
    assert subprocess.run(cmd, cwd=ROOT / "addon", capture_output=True, timeout=300).returncode == 0
    img = bpy.data.images[schema.RECOMPOSITED_IMAGE]
    w, h = img.size
    px = np.empty(w * h * 4, np.float32)
    img.pixels.foreach_get(px)
    np.testing.assert_array_equal(px.reshape(h, w, 4)[::-1, :, :3], envmaps.read_exr(one)[..., :3])
    # Nothing recomposited yet: the folder must be chosen.
    bpy.ops.wm.read_factory_settings(use_empty=True)
    rokeby.register()
    with pytest.raises(RuntimeError, match="Choose the Frames Folder"):
        bpy.ops.rokeby.farm_export_recomposite(directory=str(tmp_path / "bad"), zip_path=str(z))
    assert not (tmp_path / "bad").exists()
