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
