"""The Blender scenes of the shadow-editing tests: a dark scene lit by one point (or area) light
only (direct light, no bounces: a noise-free hard shadow edge), seen from straight above by an
orthographic camera, rendered by Cycles into a grey image whose row 0 is the top.

:func:`blender_scene` is the ball over the ground of tests/shadow/test_shadow.py that the other
shadow, deletion and hardening tests reuse; tests/shadow/test_shadow_self.py builds its own caster
on the same :func:`dark_scene`, :func:`add_light`, :func:`add_top_camera` and :func:`render`."""

from __future__ import annotations

import numpy as np
import pytest

from support import cycles

SIZE = 96  # pixels of blender_scene's top view, 4 world units wide
LIGHT = np.array([0.2, 0.1, 5.0])


def dark_scene(size: int, samples: int = 4):
    """An empty scene with the add-on registered, tiny deterministic Cycles renders of ``size``
    pixels with direct light only, and a black world. Returns ``(bpy, scene)``."""
    bpy = pytest.importorskip("bpy")
    import rokeby

    bpy.ops.wm.read_factory_settings(use_empty=True)
    rokeby.register()  # shadow edits keep their links in obj.rokeby_shadow (idempotent)
    sc = cycles(bpy.context.scene, size, samples)
    sc.cycles.max_bounces = 0  # direct light only: a noise-free hard shadow edge
    sc.render.film_transparent = False
    world = bpy.data.worlds.new("Black")
    sc.world = world
    world.color = (0, 0, 0)
    return bpy, sc


def add_light(sc, location, light_type: str = "POINT"):
    """A 3000 W light named Lamp: a hard point light, or (``"AREA"``) a 0.4-unit area light with
    enough samples for its soft penumbra."""
    import bpy

    ld = bpy.data.lights.new("Lamp", light_type)
    ld.energy = 3000.0
    if light_type == "AREA":
        ld.size = 0.4  # soft shadows: a penumbra about 3 px wide at the edge
        sc.cycles.samples = 64
    else:
        ld.shadow_soft_size = 0.0
    lamp = bpy.data.objects.new("Lamp", ld)
    sc.collection.objects.link(lamp)
    lamp.location = tuple(location)
    return lamp


def add_top_camera(sc, centre=(0.0, 0.0), ortho_scale: float = 4.0):
    """An orthographic camera 10 units above ``centre`` (x, y), looking down; the scene's camera."""
    import bpy

    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.type = "ORTHO"
    cam.data.ortho_scale = ortho_scale
    sc.collection.objects.link(cam)
    sc.camera = cam
    cam.location = (centre[0], centre[1], 10.0)
    return cam


def render(bpy, sc, path, size: int = SIZE) -> np.ndarray:
    """Renders ``sc`` to ``path`` and returns the (size, size) grey image, row 0 = top."""
    sc.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(sc.render.filepath)
    try:
        px = np.array(img.pixels[:], dtype=np.float32).reshape(size, size, 4)[..., :3].mean(-1)
    finally:
        bpy.data.images.remove(img)
    return px[::-1]  # row 0 = top of the image


def blender_scene(light_type: str = "POINT"):
    """A smooth ball (r 0.5 at z 1.5) over a 12-unit ground plane under LIGHT, seen from above
    (4 units wide, SIZE pixels). Returns ``(bpy, scene, ball, lamp, ground)``."""
    bpy, sc = dark_scene(SIZE)
    bpy.ops.mesh.primitive_plane_add(size=12)
    ground = bpy.context.object
    ground.name = "Ground"
    bpy.ops.mesh.primitive_uv_sphere_add(segments=48, ring_count=24, radius=0.5, location=(0, 0, 1.5))
    bpy.ops.object.shade_smooth()
    ball = bpy.context.object
    ball.name = "Ball"
    lamp = add_light(sc, LIGHT, light_type)
    add_top_camera(sc)
    sc.view_layers[0].update()
    return bpy, sc, ball, lamp, ground


def to_pixel(p):
    """World (x, y) on the ground → (column, row) in blender_scene's top view (4 units wide)."""
    return np.array([(p[0] / 4.0 + 0.5) * SIZE, (0.5 - p[1] / 4.0) * SIZE])


def edge_along(img, centre, direction, r_max=1.9):
    """Distance (world units) from ``centre`` along ``direction`` where the ground turns lit."""
    ts = np.linspace(0.0, r_max, 400)
    vals = []
    for t in ts:
        c, r = to_pixel(centre + direction * t)
        ci, ri = int(np.clip(c, 0, SIZE - 1)), int(np.clip(r, 0, SIZE - 1))
        vals.append(img[ri, ci])
    vals = np.asarray(vals)
    thr = 0.5 * (vals.min() + vals.max())
    # Dark inside, lit outside: the number of dark samples places the (half-intensity) edge, robust
    # to sampling noise in a soft penumbra where the first crossing is not.
    if vals[-1] <= thr:
        return np.inf
    return ts[1] * np.count_nonzero(vals <= thr)


def edited_scene():
    """blender_scene with its shadow's +x side dragged out by 35 % and the edit applied. Returns
    ``(bpy, scene, ball, lamp, ground, session, shadow_mesh, twin_light)``."""
    bpy, sc, ball, lamp, ground = blender_scene()
    from rokeby import api

    s = api.start_shadow_edit(ball, lamp, [ground], min_loop_vertices=10)
    h = s.handles(0)["points"].astype(np.float64)
    n = len(h)
    centre = h.mean(axis=0)
    m = int(np.argmax(h[:, 0]))
    s.drag(0, ((m - n // 5) % n, (m + n // 5) % n), m, centre + (h[m] - centre) * 1.35)
    s.commit()
    ob, twin = api.apply_shadow_edit(s)
    return bpy, sc, ball, lamp, ground, s, ob, twin
