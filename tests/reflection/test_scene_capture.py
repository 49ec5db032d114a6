"""The scene captured from a mirror for the viewport preview (rokeby.reflection.viewport.scene_env):
colour and distance per texel from one Cycles panorama pair, the scene left as it was, and
captures redone when, and only when, something the capture shows changes: never for a handle
drag (counted)."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from support import scene_preview as S  # noqa: E402
from rokeby import api  # noqa: E402
from rokeby.core import latlong  # noqa: E402
from rokeby.reflection.viewport import scene_env  # noqa: E402

WIDTH, SAMPLES = 64, 2


@pytest.fixture
def scene():
    sc, mirror, objects = S.build(size=16, samples=2)
    sc.rokeby_viewport_preview = True
    api.add_constraint(mirror, (-0.45, -0.8, -0.35), tuple(np.array(objects["Magenta"].location) + (0, 0, 0.25)))
    api.evaluate(force=True)
    scene_env.forget()
    yield sc, mirror, objects
    scene_env.forget()


def test_distances_are_those_a_ray_from_the_centre_meets(scene):
    sc, mirror, objects = scene
    before = (sc.camera, sc.world, sc.render.engine, mirror.visible_camera, mirror.hide_render, len(bpy.data.objects), len(bpy.data.materials))
    cap = scene_env.capture(mirror, sc, width=WIDTH, samples=SAMPLES)
    assert (sc.camera, sc.world, sc.render.engine, mirror.visible_camera, mirror.hide_render, len(bpy.data.objects), len(bpy.data.materials)) == before
    h, w = cap.texels.shape[:2]
    assert (w, h) == (WIDTH, WIDTH // 2) and cap.nbytes == w * h * 16
    assert np.all(np.isfinite(cap.texels)) and np.all(cap.texels[..., 3] >= 0)
    mirror.hide_set(True)  # scene.ray_cast sees what is visible: the mirror is not in its own capture
    dg = bpy.context.evaluated_depsgraph_get()
    from mathutils import Vector

    seen = set()
    for i in range(0, h, 3):
        for j in range(0, w, 3):
            d = latlong.uv_to_direction((j + 0.5) / w, (i + 0.5) / h)
            hit, loc, _n, _i, ob, _m = sc.ray_cast(dg, Vector(tuple(cap.origin)), Vector(tuple(d)))
            inv = cap.texels[i, j, 3]
            if not hit:
                assert inv == 0.0, (i, j)
                continue
            seen.add(ob.name)
            assert inv > 0 and abs(1.0 / inv - np.linalg.norm(np.array(loc) - cap.origin)) < 1e-3 * (1.0 / inv), (i, j, ob.name)
    assert {"Floor", "Magenta", "Red"} <= seen
    mirror.hide_set(False)


def test_a_handle_drag_never_captures_what_the_scene_shows_does(scene):
    sc, mirror, objects = scene
    scene_env.capture(mirror, sc, width=WIDTH, samples=SAMPLES)  # refresh keeps these settings
    n = scene_env.stats["captures"]
    # a drag: the green and the red handle moved in steps, the field re-evaluated after each
    c = mirror.rokeby.constraints[0]
    for step in range(4):
        c.target_handle.location.x += 0.1
        c.surface_handle.location.z += 0.02
        bpy.context.view_layer.update()
        api.evaluate()
        assert scene_env.refresh(sc) == 0
    assert scene_env.stats["captures"] == n, "a handle drag must not capture"
    # ... and what the capture shows does
    changes = [
        lambda: setattr(objects["Red"], "location", objects["Red"].location + type(objects["Red"].location)((0.0, 0.0, 0.3))),
        lambda: objects["Blue"].data.materials[0].node_tree.nodes["Principled BSDF"].inputs["Base Color"].__setattr__("default_value", (0.9, 0.9, 0.1, 1.0)),
        lambda: sc.world.node_tree.nodes["Background"].inputs["Strength"].__setattr__("default_value", 0.5),
        lambda: setattr(mirror, "location", (0.2, 0.0, 0.0)),
        lambda: objects["Yellow"].__setattr__("hide_render", True),
    ]
    for k, change in enumerate(changes):
        change()
        bpy.context.view_layer.update()
        assert scene_env.refresh(sc) == 1, f"change {k} did not recapture"
        assert scene_env.refresh(sc) == 0, f"change {k}: captured twice"
    # a light
    lamp = bpy.data.objects.new("Key", bpy.data.lights.new("Key", "POINT"))
    sc.collection.objects.link(lamp)
    bpy.context.view_layer.update()
    assert scene_env.refresh(sc) == 1
    lamp.data.energy = 500.0
    assert scene_env.refresh(sc) == 1
    assert scene_env.stats["captures"] == n + len(changes) + 2


def test_mirrors_without_the_preview_are_not_captured(scene):
    sc, mirror, _objects = scene
    sc.rokeby_viewport_preview = False
    assert scene_env.refresh(sc) == 0 and scene_env.current(mirror) is None
    sc.rokeby_viewport_preview = True
    mirror.rokeby.show_preview = False
    assert scene_env.refresh(sc) == 0 and scene_env.current(mirror) is None


@pytest.fixture
def window(monkeypatch):
    """Depsgraph updates as in a Blender window; the timers the add-on asks for are kept here."""
    from rokeby.reflection import evaluate, handlers

    timers = []
    monkeypatch.setattr(handlers, "WINDOW_UPDATES", True)
    monkeypatch.setattr(scene_env, "_pending", False)
    monkeypatch.setattr(evaluate, "_schedule", lambda fn, seconds: timers.append(fn))
    return timers


def _settle(timers, monkeypatch):
    """Run the capture timer as the event loop would once the updates have paused."""
    ours = [fn for fn in timers if fn is scene_env._timer]
    assert ours, "no capture timer was asked for"
    timers[:] = [fn for fn in timers if fn is not scene_env._timer]
    fn = ours[0]
    assert fn() > 0  # right after an update it waits (debounced)
    monkeypatch.setattr(scene_env, "_last_change", scene_env._last_change - 2 * scene_env.DEBOUNCE_SECONDS)
    assert fn() is None


def test_in_a_window_updates_recapture_after_a_pause_and_drags_do_not(scene, window, monkeypatch):
    sc, mirror, objects = scene
    scene_env.capture(mirror, sc, width=WIDTH, samples=SAMPLES)
    n = scene_env.stats["captures"]
    c = mirror.rokeby.constraints[0]
    for _ in range(3):  # a drag: a stream of updates
        c.target_handle.location.x += 0.1
        bpy.context.view_layer.update()
    _settle(window, monkeypatch)
    assert scene_env.stats["captures"] == n
    for _ in range(3):  # a transform of a cube in progress: one capture once it pauses
        objects["Red"].location.z += 0.1
        bpy.context.view_layer.update()
    assert [fn for fn in window if fn is scene_env._timer] == [scene_env._timer]  # one timer for the whole stream
    _settle(window, monkeypatch)
    assert scene_env.stats["captures"] == n + 1


def test_another_file_drops_the_captures(scene, tmp_path):
    sc, mirror, _objects = scene
    scene_env.capture(mirror, sc, width=WIDTH, samples=SAMPLES)
    assert scene_env.current(mirror) is not None
    path = str(tmp_path / "other.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    assert not scene_env._captures  # captures are never saved: the reopened mirror captures anew
    mirror = bpy.data.objects["Mirror"]
    assert scene_env.current(mirror) is None


def test_the_capture_scene_operator_captures_every_previewed_mirror_again(scene):
    sc, mirror, _objects = scene
    scene_env.capture(mirror, sc, width=WIDTH, samples=SAMPLES)
    n = scene_env.stats["captures"]
    assert bpy.ops.rokeby.preview_capture() == {"FINISHED"}
    assert scene_env.stats["captures"] == n + 1 and scene_env.current(mirror).width == WIDTH  # its settings kept
    sc.rokeby_viewport_preview = False
    assert not bpy.ops.rokeby.preview_capture.poll()
