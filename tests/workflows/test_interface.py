"""The add-on's interface by Blender's conventions (problem 7): sub-panels, menus that
name every operator (F3 search reads menus), a poll on every operator that says why it is
unavailable, messages in the words of the buttons, progress in the status bar, Set Up Compositing
Passes that reports and undoes its changes, settings saved with the .blend, add-on preferences
the code reads, and an EXR sequence operator for users of the extension zip."""

import ast
import os
import re
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import rokeby  # noqa: E402
from rokeby import api  # noqa: E402
from rokeby.blender import compat, progress  # noqa: E402
from rokeby.reflection import mirror_state  # noqa: E402
from rokeby.core import words  # noqa: E402

from support import ROOT  # noqa: E402

ADDON = ROOT / "addon" / "rokeby"


@pytest.fixture
def registered():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    rokeby.register()
    mirror_state.reset()
    yield bpy.context.scene
    rokeby.unregister()


def _operators():
    """Every operator class of the add-on's modules (each feature package registers its own)."""
    out = {}
    for name, module in list(sys.modules.items()):
        if not name.startswith("rokeby.") or module is None:
            continue
        for obj in vars(module).values():
            if isinstance(obj, type) and issubclass(obj, bpy.types.Operator) and getattr(obj, "bl_idname", "").startswith("rokeby."):
                out[obj.bl_idname] = obj
    return out


def _poll_error(idname) -> str:
    """The message a refused operator gives (what its greyed-out button's tooltip says)."""
    mod, name = idname.split(".")
    with pytest.raises(RuntimeError) as info:
        getattr(getattr(bpy.ops, mod), name)()
    return str(info.value)


class _Recorder:
    """A window manager that records the progress calls made to it."""

    def __init__(self):
        self.calls = []

    def progress_begin(self, lo, hi):
        self.calls.append(("begin", lo, hi))

    def progress_update(self, value):
        self.calls.append(("update", value))

    def progress_end(self):
        self.calls.append(("end",))


@pytest.fixture
def recorder(monkeypatch):
    rec = _Recorder()
    monkeypatch.setattr(progress, "window_manager", lambda context=None: rec)
    return rec


def _check_progress(calls):
    """One begin, updates that never go back and reach the end, one end last."""
    assert calls and calls[0][0] == "begin" and calls[-1] == ("end",), calls
    hi = calls[0][2]
    values = [c[1] for c in calls if c[0] == "update"]
    assert values == sorted(values) and values[-1] == hi, calls
    assert [c[0] for c in calls].count("begin") == 1 and [c[0] for c in calls].count("end") == 1


def _sphere(name="Ball"):
    bpy.ops.mesh.primitive_uv_sphere_add(segments=24, ring_count=12)
    ob = bpy.context.object
    ob.name = name
    return ob


# --- panels and menus -----------------------------------------------------------------------------

def test_sidebar_has_sub_panels_in_order(registered):
    from rokeby.appearance import ui as appearance_ui
    from rokeby.reflection import ui

    subs = ui.MIRROR_PANELS[1:]
    assert [p.bl_label for p in subs] == ["Constraints", "Regions", "Settings", "Render"]
    assert all(p.bl_parent_id == "ROKEBY_PT_main" for p in subs)
    assert [p.bl_order for p in subs] == sorted({p.bl_order for p in subs})
    for p in (*ui.MIRROR_PANELS, *appearance_ui.PANELS):
        assert hasattr(bpy.types, p.bl_idname), p.bl_idname
    assert appearance_ui.PANELS[1].bl_parent_id == "ROKEBY_PT_appearance"
    # The top-level panels of the Rokeby tab are ordered: reflections, shadows, appearance.
    from rokeby.shadow.ui import ROKEBY_PT_shadow

    assert ui.ROKEBY_PT_main.bl_order < ROKEBY_PT_shadow.bl_order < appearance_ui.ROKEBY_PT_appearance.bl_order
    # The sub-panels show only with an active mirror.
    ball = _sphere()
    assert not any(p.poll(bpy.context) for p in subs)
    api.add_mirror(ball)
    assert all(p.poll(bpy.context) for p in subs)


def test_menus_name_every_operator(registered):
    from support.ui import Layout

    from rokeby.reflection import ui

    log = []
    ui.VIEW3D_MT_rokeby.draw(type("M", (), {"layout": Layout(log)})(), bpy.context)
    named = {idname for kind, idname in log if kind == "operator"}
    assert named == set(_operators()), set(_operators()) ^ named
    # Object ▸ Rokeby and the object context menu open that menu.
    for menu in ("VIEW3D_MT_object", "VIEW3D_MT_object_context_menu"):
        funcs = getattr(bpy.types, menu).draw._draw_funcs
        assert ui.draw_menu_entry in funcs, menu
        log = []
        ui.draw_menu_entry(type("M", (), {"layout": Layout(log)})(), bpy.context)
        assert ("menu", "VIEW3D_MT_rokeby") in log
    rokeby.unregister()
    assert ui.draw_menu_entry not in bpy.types.VIEW3D_MT_object.draw._draw_funcs
    rokeby.register()


# --- poll and its messages ----------------------------------------------------------------------

def test_every_operator_has_a_poll_that_says_why(registered):
    ops = _operators()
    assert len(ops) > 25
    assert not [i for i, cls in ops.items() if not callable(getattr(cls, "poll", None))]
    # An empty scene: whatever cannot run says why, in a sentence (not "context is incorrect").
    refused = []
    for idname in sorted(ops):
        mod, name = idname.split(".")
        if not getattr(getattr(bpy.ops, mod), name).poll():
            msg = _poll_error(idname)
            assert "context is incorrect" not in msg and len(msg.split("poll()", 1)[1].split()) >= 4, msg
            refused.append(name)
    assert {"mirror_add", "mirror_remove", "constraint_add", "update", "shadow_start", "shadow_apply",
            "appearance_paint", "composite_render"} <= set(refused)


def test_poll_messages_name_the_buttons(registered):
    sc = registered
    lamp = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT"))
    sc.collection.objects.link(lamp)
    empty = bpy.data.objects.new("Empty", None)
    sc.collection.objects.link(empty)
    bpy.context.view_layer.objects.active = empty
    assert "'Empty' is an empty: select a mesh" in _poll_error("rokeby.mirror_add")
    ball = _sphere()
    assert "'Ball' is not a Rokeby mirror: click Add Mirror first" in _poll_error("rokeby.constraint_add")
    assert "Select the mesh" not in _poll_error("rokeby.shadow_apply") and "Edit Shadow Boundaries" in _poll_error("rokeby.shadow_apply")
    assert "Set Up Appearance Painting" in _poll_error("rokeby.appearance_paint")
    assert bpy.ops.rokeby.mirror_add() == {"FINISHED"}
    assert "already a Rokeby mirror" in _poll_error("rokeby.mirror_add")
    assert "has no constraints to remove: add one with Add Reflection Constraint" in _poll_error("rokeby.constraint_remove")
    assert "has no regions to remove" in _poll_error("rokeby.region_remove")
    # A refusal from the API, relayed by an operator, names the button too.
    _sphere("Other")
    with pytest.raises(RuntimeError) as info:
        bpy.ops.rokeby.reflection_map(mirror="Other")
    assert "Add Mirror" in str(info.value) and "add_mirror" not in str(info.value)
    bpy.context.view_layer.objects.active = lamp
    assert "'Lamp' is a light, not a mesh" in _poll_error("rokeby.shadow_start")


def _api_names():
    from rokeby import appearance, compositing

    names = {n for n in api.__all__ if "_" in n}
    names |= {f"{mod.__name__.rsplit('.', 1)[1]}.{n}" for mod in (appearance, compositing) for n in dir(mod)
              if callable(getattr(mod, n)) and not n.startswith("_")}
    names |= {"setup()", "remove_texture()", "setup_passes"}
    return names


def _message_strings(path: Path):
    """(line, text) of every string in a message: raised errors, reports, poll messages, panel
    labels, report warnings (docstrings and the command-line tools' help excluded)."""
    tree = ast.parse(path.read_text())
    out = []
    for node in ast.walk(tree):
        call = None
        if isinstance(node, ast.Raise) and isinstance(node.exc, ast.Call):
            call = node.exc
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in {"report", "poll_message_set", "label", "warn", "__init__", "_fail"}:
            call = node
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "_fail":
            call = node
        if call is None:
            continue
        for sub in ast.walk(call):
            if isinstance(sub, ast.Constant) and isinstance(sub.value, str):
                out.append((sub.lineno, sub.value))
    return out


def test_no_message_names_an_api_function():
    pattern = re.compile(r"(?<!\w)(" + "|".join(sorted(map(re.escape, _api_names()), key=len, reverse=True)) + r")(?![\w])")
    hits = []
    for path in sorted(ADDON.rglob("*.py")):
        if path.relative_to(ADDON).as_posix() in ("demo.py", "composite.py"):  # a demo script's printout, the command line's help
            continue
        for line, text in _message_strings(path):
            if pattern.search(text):
                hits.append(f"{path.name}:{line}: {text[:100]}")
    assert not hits, "messages that name API functions instead of buttons:\n" + "\n".join(hits)


def test_words_and_statuses():
    assert words.kind("EMPTY") == "an empty" and words.kind("LIGHT") == "a light" and words.kind("ARMATURE") == "an armature"
    assert words.status("OK") == "OK" and words.status("WARNING") == "Warning"
    hits = [f"{p.name}:{i}" for p in ADDON.rglob("*.py") for i, ln in enumerate(p.read_text().splitlines(), 1) if ".title()" in ln]
    assert not hits, hits


def test_status_line_reads_ok(registered):
    from support.ui import draw_sidebar

    ball = _sphere()
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    registered.collection.objects.link(cam)
    registered.camera = cam
    cam.location = (0.0, -5.0, 0.0)
    api.add_mirror(ball)
    api.add_constraint(ball, (0.0, -1.0, 0.0), eye=(0.0, -5.0, 0.0))
    reps = api.evaluate()
    bpy.context.view_layer.objects.active = ball
    log = []
    draw_sidebar(log)
    labels = [t for kind, t in log if kind == "label"]
    status = words.status(reps["Ball"].status)
    assert any(t.startswith(f"{status}: 1 constraint(s)") for t in labels), labels
    assert not any(t.startswith("Ok:") for t in labels)


def test_native_missing_message_fits_how_the_add_on_is_installed(monkeypatch):
    from rokeby.core import native

    assert "make" in native.missing_hint() and not native.is_extension()
    monkeypatch.setattr(native, "__package__", "bl_ext.user_default.rokeby")
    hint = native.missing_hint()
    assert native.is_extension() and "make" not in hint and "native wheel" in hint and "reinstall" in hint.lower()


# --- progress ------------------------------------------------------------------------------------

def test_progress_is_silent_in_background_mode():
    assert bpy.app.background and progress.window_manager() is None
    with progress.Progress(bpy.context, 3) as p:  # nothing to call: no error either
        p.step(5)
    assert p.done == 3


def test_geodesic_switch_and_map_capture_show_progress(registered, recorder):
    ball = _sphere()
    api.add_mirror(ball)
    api.add_constraint(ball, (0.0, -1.0, 0.0), eye=(0.0, -5.0, 0.0))
    api.evaluate()
    assert bpy.ops.rokeby.distance_set(mirror="Ball", metric="GEODESIC") == {"FINISHED"}
    assert ball.rokeby.metric == "GEODESIC" and api.report(ball).status != "ERROR"
    _check_progress(recorder.calls)
    recorder.calls.clear()
    ball.rokeby.map_resolution, ball.rokeby.map_samples = "256", 1
    registered.render.engine = "CYCLES"
    assert bpy.ops.rokeby.reflection_map(mirror="Ball") == {"FINISHED"}
    _check_progress(recorder.calls)


# --- Set Up Compositing Passes ---------------------------------------------------------------------

def test_setup_passes_reports_every_change_and_undoes(registered, capfd):
    sc = registered
    ball = _sphere()
    mat = bpy.data.materials.new("Chrome")
    mat.use_nodes = True
    ball.data.materials.append(mat)
    st = sc.render.image_settings
    st.file_format, st.color_depth = "PNG", "8"
    vl = bpy.context.view_layer
    bpy.ops.ed.undo_push(message="before")
    assert bpy.ops.rokeby.composite_setup_passes() == {"FINISHED"}
    out = capfd.readouterr()
    text = out.out + out.err
    # Blender's own names of the formats: 5.0+ add the extension ("OpenEXR MultiLayer (.exr)").
    assert re.search(r"Output file format switched to OpenEXR MultiLayer( \(\.exr\))? \(was PNG( \(\.png\))?\)", text), text
    assert "Output colour depth switched to 32-bit (was 8-bit)" in text, text
    assert re.search(r"Passes enabled on view layer: .*Diffuse Direct", text) and "Shader AOVs added: rokeby_reflocc" in text
    assert "Pass index given to 1 object(s): Ball" in text
    assert compat.is_multilayer_exr(st) and vl.use_pass_diffuse_direct
    assert "UNDO" in bpy.types.ROKEBY_OT_composite_setup_passes.bl_options
    bpy.ops.ed.undo_push(message="Set Up Compositing Passes")
    bpy.ops.ed.undo()
    sc, vl = bpy.context.scene, bpy.context.view_layer
    st = sc.render.image_settings
    assert (st.file_format, st.color_depth) == ("PNG", "8")
    assert not vl.use_pass_diffuse_direct and len(vl.aovs) == 0 and bpy.data.objects["Ball"].pass_index == 0
    # A second run on a scene already set up changes nothing and says so.
    bpy.ops.ed.redo()
    capfd.readouterr()
    assert bpy.ops.rokeby.composite_setup_passes() == {"FINISHED"}
    out = capfd.readouterr()
    assert "already set up; nothing changed" in out.out + out.err


# --- settings saved with the file, preferences for the machine ------------------------------------

def test_scene_settings_survive_save_and_reload(registered, tmp_path):
    sc = registered
    sc.rokeby_viewport_preview = True
    brush = sc.rokeby_appearance_brush
    brush.brush, brush.radius, brush.preview_model, brush.target = "sharpen", 0.37, "PHONG", "TEXTURE"
    path = str(tmp_path / "settings.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    assert not bpy.context.scene.rokeby_viewport_preview
    bpy.ops.wm.open_mainfile(filepath=path)
    sc = bpy.context.scene
    brush = sc.rokeby_appearance_brush
    assert sc.rokeby_viewport_preview
    assert (brush.brush, round(brush.radius, 5), brush.preview_model, brush.target) == ("sharpen", 0.37, "PHONG", "TEXTURE")
    assert not hasattr(bpy.types.WindowManager, "rokeby_viewport_preview")
    assert not hasattr(bpy.types.WindowManager, "rokeby_appearance_brush")


def test_preferences_are_the_add_on_s_and_are_read(tmp_path):
    import addon_utils

    from rokeby.appearance import preview as appearance_preview
    from rokeby.blender import prefs
    from rokeby.reflection.render import reflmap

    bpy.ops.wm.read_factory_settings(use_empty=True)
    rokeby.unregister()
    # Without Blender listing the add-on (a script's rokeby.register()), the defaults answer.
    assert {k: getattr(prefs.get(), k) for k in prefs.DEFAULTS} == prefs.DEFAULTS
    addon_utils.enable("rokeby", default_set=True, handle_error=None)
    try:
        assert prefs.RokebyPreferences.bl_idname == rokeby.__name__ == prefs.PACKAGE
        p = bpy.context.preferences.addons["rokeby"].preferences
        assert {k: getattr(p, k) for k in prefs.DEFAULTS} == prefs.DEFAULTS  # the class's defaults are DEFAULTS
        # The cache folder: an unsaved file's maps are written there (not packed).
        p.cache_folder = str(tmp_path / "cache")
        assert reflmap.cache_dir() == str(tmp_path / "cache") + "/"
        ball = _sphere()
        api.add_mirror(ball)
        ball.rokeby.map_resolution, ball.rokeby.map_samples = "256", 1
        bpy.context.scene.render.engine = "CYCLES"
        assert bpy.ops.rokeby.reflection_map(mirror="Ball") == {"FINISHED"}
        assert f"{reflmap.map_stem(ball)}.exr" in os.listdir(tmp_path / "cache") and reflmap.image_for(ball).packed_file is None
        # GPU opt-in: with GPU previews off, the painted-appearance preview cannot be switched on.
        p.gpu_viewport_preview = False
        assert not appearance_preview.enabled() and not bpy.ops.rokeby.appearance_preview.poll()
        assert "add-on preferences" in _poll_error("rokeby.appearance_preview")
        p.gpu_viewport_preview = True
        assert bpy.ops.rokeby.appearance_preview.poll()
        # The compositing backend: operators not given one use the preferences' default.
        from rokeby.compositing import ui as compositing_ui

        class Op:
            edit, amount, k_d, k_r, image_name, backend, fit, noise_tolerance = "EMBOSS", 0.5, 1.0, 1.0, "x", "CPU", "QP", 0.0
            properties = type("Props", (), {"is_property_set": staticmethod(lambda name: False)})()

        assert compositing_ui._edit_args(Op(), bpy.context)["backend"] == "cpu"
        p.compositing_backend = "GPU"
        assert compositing_ui._edit_args(Op(), bpy.context)["backend"] == "blender_gpu"
        Op.properties = type("Props", (), {"is_property_set": staticmethod(lambda name: name == "backend")})()
        assert compositing_ui._edit_args(Op(), bpy.context)["backend"] == "cpu"  # given: the operator's own
    finally:
        addon_utils.disable("rokeby", default_set=True)
        rokeby.unregister()


def test_preferences_work_as_an_extension(tmp_path):
    """As an extension the package is bl_ext.<repository>.rokeby: the preferences' bl_idname
    follows it, Blender finds them, and a missing native core is explained for the zip."""
    ext = tmp_path / "ext" / "bl_ext" / "user_default"
    ext.mkdir(parents=True)
    shutil.copytree(ADDON, ext / "rokeby", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(ROOT / "shaders", ext / "rokeby" / "shaders")  # where the zip has them
    script = textwrap.dedent(f"""
        import sys, types, importlib
        import bpy
        for name in list(sys.modules):
            if name == "bl_ext" or name.startswith("bl_ext."):
                del sys.modules[name]
        pkg = types.ModuleType("bl_ext"); pkg.__path__ = [{str(tmp_path / "ext" / "bl_ext")!r}]
        sys.modules["bl_ext"] = pkg
        sub = types.ModuleType("bl_ext.user_default"); sub.__path__ = [{str(ext)!r}]
        sys.modules["bl_ext.user_default"] = sub
        mod = importlib.import_module("bl_ext.user_default.rokeby")
        addon = bpy.context.preferences.addons.new()
        addon.module = "bl_ext.user_default.rokeby"
        mod.register()
        prefs = importlib.import_module("bl_ext.user_default.rokeby.blender.prefs")
        native = importlib.import_module("bl_ext.user_default.rokeby.core.native")
        print("IDNAME", prefs.RokebyPreferences.bl_idname, prefs.RokebyPreferences.is_registered)
        addon.preferences.compositing_backend = "GPU"
        print("READ", prefs.get().compositing_backend)
        print("EXTENSION", native.is_extension(), "native wheel" in native.missing_hint())
        mod.unregister()
        """)
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    assert "IDNAME bl_ext.user_default.rokeby True" in out.stdout, out.stdout + out.stderr[-2000:]
    assert "READ GPU" in out.stdout and "EXTENSION True True" in out.stdout


# --- the EXR sequence operator ---------------------------------------------------------------------

def _render_frame(path):
    from support import cycles

    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = cycles(bpy.context.scene, 24, 4)
    sc.render.resolution_y = 16
    from rokeby import compositing as C
    from rokeby import envmaps

    envmaps.use_studio_world(sc, "forest")
    bpy.ops.mesh.primitive_uv_sphere_add(segments=24, ring_count=12)
    bpy.ops.object.shade_smooth()
    mat = bpy.data.materials.new("red")
    mat.use_nodes = True
    mat.node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value = 0.3
    bpy.context.object.data.materials.append(mat)
    bpy.ops.object.camera_add(location=(0.0, -4.0, 0.0), rotation=(np.pi / 2, 0, 0))
    sc.camera = bpy.context.object
    C.render_passes(sc, str(path))


def test_sequence_operator_recomposites_every_frame_and_resumes(registered, tmp_path, recorder):
    import OpenEXR

    from rokeby import compositing as C

    frames = tmp_path / "frames"
    frames.mkdir()
    _render_frame(frames / "shot_0001.exr")
    rokeby.register()
    for k in (2, 3):
        shutil.copy(frames / "shot_0001.exr", frames / f"shot_{k:04d}.exr")
    (frames / "notes.txt").write_text("not a frame")
    out = tmp_path / "out"
    args = dict(directory=str(frames), pattern="shot_####.exr", output_directory=str(out), edit="EMBOSS", amount=0.4)
    assert bpy.ops.rokeby.composite_sequence(**args) == {"FINISHED"}
    names = sorted(os.listdir(out))
    assert names == ["shot_0001.exr", "shot_0002.exr", "shot_0003.exr"]
    _check_progress(recorder.calls)
    assert [c for c in recorder.calls if c[0] == "begin"] == [("begin", 0, 3)]
    # Each output is the frame recomposited with the edit: finite, the frame's size, not the input.
    inp = C.read_exr(str(frames / "shot_0001.exr"))
    with OpenEXR.File(str(out / "shot_0002.exr")) as f:
        rgb = np.asarray(f.parts[0].channels["RGB"].pixels, np.float32)
    assert rgb.shape == (16, 24, 3) and np.isfinite(rgb).all()
    assert (np.abs(rgb - inp.image[..., :3]) > 1e-4).any(-1).sum() > 10
    # The command line (python -m rokeby.composite --sequence, the farm's path) with the same edit
    # writes the same frames, bit for bit.
    cli = subprocess.run([sys.executable, "-m", "rokeby.composite", "--sequence", str(frames), str(tmp_path / "cli"),
                          "--pattern", "shot_####.exr", "--emboss", "0.4"], capture_output=True, text=True,
                         cwd=ROOT / "addon", timeout=600)
    assert cli.returncode == 0, cli.stderr[-2000:]
    for n in names:
        with OpenEXR.File(str(tmp_path / "cli" / n)) as f, OpenEXR.File(str(out / n)) as g:
            np.testing.assert_array_equal(np.asarray(f.parts[0].channels["RGB"].pixels), np.asarray(g.parts[0].channels["RGB"].pixels))
    # Resume: a frame whose output is gone is redone; frames done are kept as they are.
    kept = {n: os.stat(out / n).st_mtime_ns for n in ("shot_0001.exr", "shot_0003.exr")}
    os.remove(out / "shot_0002.exr")
    (frames / "shot_0004.exr").write_bytes(b"not an EXR")  # a broken frame fails, the others go on
    with pytest.raises(RuntimeError) as info:
        bpy.ops.rokeby.composite_sequence(**args)
    msg = str(info.value)
    assert "1 frame(s) recomposited" in msg and "2 already done" in msg and "shot_0004.exr" in msg and "run again" in msg
    assert sorted(os.listdir(out)) == ["shot_0001.exr", "shot_0002.exr", "shot_0003.exr"]
    assert {n: os.stat(out / n).st_mtime_ns for n in kept} == kept
    shutil.copy(frames / "shot_0001.exr", frames / "shot_0004.exr")  # the frame is fixed: run again
    recorder.calls.clear()
    assert bpy.ops.rokeby.composite_sequence(**args) == {"FINISHED"}
    assert "shot_0004.exr" in os.listdir(out)
    assert [c for c in recorder.calls if c[0] == "update"][-1] == ("update", 4)
    # Bad inputs are refused with what is wrong.
    with pytest.raises(RuntimeError, match="no frames matching"):
        bpy.ops.rokeby.composite_sequence(directory=str(frames), pattern="nothing_*.exr")
    with pytest.raises(RuntimeError, match="Output Folder must differ"):
        bpy.ops.rokeby.composite_sequence(directory=str(frames), output_directory=str(frames))


def test_sequence_frames_sort_by_number(tmp_path):
    from rokeby.compositing.ui import sequence_frames

    for n in ("f_10.exr", "f_2.exr", "f_1.exr", "g.exr", "f_3.png"):
        (tmp_path / n).write_bytes(b"")
    assert [Path(p).name for p in sequence_frames(str(tmp_path), "f_*.exr")] == ["f_1.exr", "f_2.exr", "f_10.exr"]
    assert [Path(p).name for p in sequence_frames(str(tmp_path), "f_#.exr")] == ["f_1.exr", "f_2.exr"]
