"""Highlight editing (paper Figs. 6 and 7): a highlight is the reflection of a light, so a
constraint whose green handle is the light moves it, two stretch it, and shadows stay put."""

import math

import numpy as np
import pytest
from support import cycles

bpy = pytest.importorskip("bpy")

import rokeby  # noqa: E402
from rokeby import api  # noqa: E402
from rokeby.reflection import mirror_state  # noqa: E402
from rokeby.core.errors import RokebyError  # noqa: E402

SIZE = 64


@pytest.fixture
def lit_ball():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    rokeby.register()
    mirror_state.reset()
    sc = bpy.context.scene
    cycles(sc, SIZE, 16, seed=1)
    sc.world = bpy.data.worlds.new("Dim")
    sc.world.color = (0.02, 0.02, 0.02)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=64, ring_count=32)
    bpy.ops.object.shade_smooth()
    ball = bpy.context.object
    ball.name = "Ball"
    mat = bpy.data.materials.new("Glossy")
    mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Metallic"].default_value = 1.0
    bsdf.inputs["Roughness"].default_value = 0.15
    ball.data.materials.append(mat)
    bpy.ops.mesh.primitive_plane_add(size=20, location=(0.0, 0.0, -1.0))
    floor = bpy.context.object
    floor.name = "Floor"
    light = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT"))
    light.data.energy = 800.0
    light.data.shadow_soft_size = 0.05
    light.location = (1.5, -2.0, 2.5)
    sc.collection.objects.link(light)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    sc.collection.objects.link(cam)
    sc.camera = cam
    cam.location = (0.0, -5.0, 0.6)
    cam.rotation_euler = (math.radians(85), 0.0, 0.0)
    api.add_mirror(ball)
    return ball, floor, light


def _render(tmp_path, name):
    sc = bpy.context.scene
    sc.render.filepath = str(tmp_path / f"{name}.png")
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(sc.render.filepath)
    try:
        return np.array(img.pixels[:], dtype=np.float32).reshape(SIZE, SIZE, 4)[::-1, :, :3]
    finally:
        bpy.data.images.remove(img)


def _pixel(point):
    """(row, column) of a world point in the rendered image (row 0 at the top)."""
    from bpy_extras.object_utils import world_to_camera_view  # noqa: PLC0415
    from mathutils import Vector  # noqa: PLC0415

    sc = bpy.context.scene
    co = world_to_camera_view(sc, sc.camera, Vector(point))
    return np.array([(1.0 - co.y) * SIZE, co.x * SIZE])


def _brightest_on_ball(img, ball_mask):
    lum = np.where(ball_mask, img.mean(-1), -1.0)
    return np.array(np.unravel_index(np.argmax(lum), lum.shape), np.float64) + 0.5


def _ball_mask():
    """Pixels well inside the ball's silhouette: the projections of dense points on the unit
    sphere's visible side, eroded by one pixel."""
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(60000, 3))
    pts /= np.linalg.norm(pts, axis=1, keepdims=True)
    bpy.context.view_layer.update()
    eye = np.array(bpy.context.scene.camera.matrix_world.translation)
    pts = pts[((eye - pts) * pts).sum(1) > 0]
    mask = np.zeros((SIZE, SIZE), bool)
    rc = np.array([_pixel(p) for p in pts[::4]]).astype(int)
    ok = (rc >= 0).all(1) & (rc < SIZE).all(1)
    mask[rc[ok, 0], rc[ok, 1]] = True
    inner = mask.copy()
    inner[1:-1, 1:-1] = mask[1:-1, 1:-1] & mask[:-2, 1:-1] & mask[2:, 1:-1] & mask[1:-1, :-2] & mask[1:-1, 2:]
    return inner


def test_highlight_moves_and_stretches_while_shadows_stay(lit_ball, tmp_path):
    ball, floor, light = lit_ball
    mask = _ball_mask()
    plain = _render(tmp_path, "plain")
    at = api.physical_highlight(ball, light)
    assert np.linalg.norm(_brightest_on_ball(plain, mask) - _pixel(at)) < 3.0  # found where it is
    index = api.add_highlight_constraint(ball, light)
    c = ball.rokeby.constraints[index]
    assert c.target_handle.parent == light
    api.add_region(ball, "EUCLIDEAN", center=(0.0, -1.0, 0.0), radius=0.9, border=0.3)
    api.evaluate()
    assert api.install_render_nodes(ball) == 1
    fresh = _render(tmp_path, "fresh")
    assert np.linalg.norm(_brightest_on_ball(fresh, mask) - _pixel(at)) < 3.0  # a fresh one: no change
    # Drag the red handle to the left: the highlight follows it.
    goal = np.array([-0.45, -0.8, 0.4])  # lit and seen: a highlight cannot go into the shadow
    goal /= np.linalg.norm(goal)
    c.surface_handle.location = goal
    api.evaluate()
    moved = _render(tmp_path, "moved")
    peak = _brightest_on_ball(moved, mask)
    assert np.linalg.norm(peak - _pixel(goal)) < 3.0, (peak, _pixel(goal))
    assert np.linalg.norm(peak - _pixel(at)) > 8.0
    # Shadows stay: the floor (everything that is not the ball, a margin left for the rim)
    # renders as before.
    floor_px = ~mask
    for _ in range(2):
        floor_px[1:-1, 1:-1] &= floor_px[:-2, 1:-1] & floor_px[2:, 1:-1] & floor_px[1:-1, :-2] & floor_px[1:-1, 2:]
    assert np.abs(moved - plain)[floor_px].max(-1).mean() < 0.01
    assert np.percentile(np.abs(moved - plain)[floor_px].max(-1), 99) < 0.08
    # Moving the light carries the green handle with it.
    before = np.array(c.target_handle.matrix_world.translation)
    light.location.x += 0.5
    bpy.context.view_layer.update()
    assert np.allclose(np.array(c.target_handle.matrix_world.translation) - before, (0.5, 0.0, 0.0), atol=1e-5)
    light.location.x -= 0.5
    bpy.context.view_layer.update()
    # A second constraint at the original spot stretches the highlight over both (Fig. 6).
    api.add_highlight_constraint(ball, light, at)
    api.evaluate()
    stretched = _render(tmp_path, "stretched")
    lum = stretched.mean(-1)
    for point in (goal, at):
        r, col = _pixel(point).astype(int)
        assert lum[max(r - 2, 0):r + 3, max(col - 2, 0):col + 3].max() > 0.5 * lum[mask].max(), point


def test_highlight_refusals(lit_ball):
    ball, floor, light = lit_ball
    with pytest.raises(RokebyError, match="not a light"):
        api.add_highlight_constraint(ball, floor)
    light.location = (0.0, 3.0, 0.0)  # behind the ball: nothing the camera sees is lit
    with pytest.raises(RokebyError, match="faces the eye and is lit"):
        api.physical_highlight(ball, light)
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    bpy.context.scene.collection.objects.link(sun)
    sun.rotation_euler = (math.radians(60), 0.0, math.radians(20))
    p = api.physical_highlight(ball, sun)
    assert np.isfinite(p).all() and abs(np.linalg.norm(p) - 1.0) < 5e-3  # on a facet of the unit sphere


def test_highlight_operator(lit_ball):
    ball, floor, light = lit_ball
    for ob in bpy.context.view_layer.objects:
        ob.select_set(False)
    with pytest.raises(RuntimeError, match="select one light"):
        bpy.ops.rokeby.highlight_add(mirror="Ball")
    assert len(ball.rokeby.constraints) == 0  # a refusal changes nothing
    light.select_set(True)
    assert bpy.ops.rokeby.highlight_add(mirror="Ball") == {"FINISHED"}
    assert ball.rokeby.constraints[0].target_handle.parent == light
    with pytest.raises(RuntimeError, match="'Floor' is not a light object"):
        bpy.ops.rokeby.highlight_add(mirror="Ball", light="Floor")
    assert len(ball.rokeby.constraints) == 1
