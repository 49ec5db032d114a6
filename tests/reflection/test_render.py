"""Final renders show the edit: Cycles pixels of a chrome ball under a real HDR (bpy's forest.exr)."""


import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from rokeby import api  # noqa: E402
from rokeby.blender import compat  # noqa: E402

from support.reflection import CHROME_BALL_SIZE as SIZE  # noqa: E402  (the chrome_ball fixture: tests/reflection/conftest.py)


def _render(tmp_path, name):
    sc = bpy.context.scene
    sc.render.filepath = str(tmp_path / f"{name}.png")
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(sc.render.filepath)
    try:
        return np.array(img.pixels[:], dtype=np.float32).reshape(SIZE, SIZE, 4)[..., :3]
    finally:
        bpy.data.images.remove(img)


def test_cycles_render_shows_the_edit_and_nothing_else(chrome_ball, tmp_path):
    ball, mat = chrome_ball
    plain = _render(tmp_path, "plain")
    api.add_mirror(ball)
    api.add_constraint(ball, (0.0, -1.0, 0.0), eye=(0.0, -4.0, 0.0))
    api.evaluate()
    assert api.install_render_nodes(ball) == 1
    fresh = _render(tmp_path, "fresh")
    # A fresh constraint is the identity: n' = normalize(reflect(-V, N) + V) = N.
    diff = np.abs(fresh - plain).max(-1)
    assert diff.mean() < 2e-3 and np.percentile(diff, 99.5) < 0.02
    green = ball.rokeby.constraints[0].target_handle
    green.location.z += 3.0
    api.add_region(ball, "EUCLIDEAN", center=(0.0, -1.0, 0.0), radius=0.6, border=0.2)
    api.evaluate()
    edited = _render(tmp_path, "edited")
    changed = np.abs(edited - fresh).max(-1) > 0.05
    assert changed.mean() > 0.02  # the edit is visible
    # Pixels whose surface point is outside the region are unchanged: on this orthographic-ish
    # view the region projects to a disc around the image centre (radius 0.6 of the unit ball).
    ys, xs = np.mgrid[0:SIZE, 0:SIZE]
    # half-width of the view at distance 4 with the default 50 mm lens (36 mm sensor): 4 * 18 / 50
    half = 4.0 * 18.0 / 50.0
    px = (xs + 0.5) / SIZE * 2 - 1
    py = 1 - (ys + 0.5) / SIZE * 2
    far = np.hypot(px, py) * half > 0.75  # well outside the region's projection
    assert changed[far].mean() < 0.005  # noise allowance: 8 samples
    assert changed[~far].mean() > 0.1
    # Removing the nodes restores the plain render.
    assert api.remove_render_nodes(ball) == 1
    assert not [n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeGroup"]
    again = _render(tmp_path, "again")
    np.testing.assert_allclose(again, plain, atol=1e-6)


def test_render_nodes_operator_and_refusals(chrome_ball):
    ball, mat = chrome_ball
    with pytest.raises(RuntimeError, match="not a Rokeby mirror"):
        bpy.ops.rokeby.render_nodes(mirror="Ball")
    api.add_mirror(ball)
    assert bpy.ops.rokeby.render_nodes(mirror="Ball") == {"FINISHED"}
    assert bpy.ops.rokeby.render_nodes(mirror="Ball") == {"FINISHED"}  # idempotent: one group
    groups = [n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeGroup"]
    assert len(groups) == 1 and groups[0].node_tree.name == "Rokeby Edited Normal"
    assert bpy.ops.rokeby.render_nodes(mirror="Ball", action="REMOVE") == {"FINISHED"}
    assert not [n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeGroup"]


def test_bump_map_passes_through_and_is_restored(chrome_ball):
    ball, mat = chrome_ball
    tree = mat.node_tree
    bump = tree.nodes.new("ShaderNodeBump")
    bsdf = tree.nodes["Principled BSDF"]
    tree.links.new(bump.outputs["Normal"], bsdf.inputs["Normal"])
    api.add_mirror(ball)
    assert api.install_render_nodes(ball) == 1
    group = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeGroup")
    assert group.inputs["Normal"].links[0].from_node == bump
    assert bsdf.inputs["Normal"].links[0].from_node == group
    api.remove_render_nodes(ball)
    assert bsdf.inputs["Normal"].links[0].from_node == bump


def test_freeze_in_renders(chrome_ball, tmp_path):
    ball, _ = chrome_ball
    api.add_mirror(ball)
    api.add_constraint(ball, (0.0, -1.0, 0.0), (0.0, -2.0, 3.0), eye=(0.0, -4.0, 0.0))
    api.evaluate()
    api.install_render_nodes(ball)
    live = _render(tmp_path, "live")
    api.freeze(ball, True, eye=(0.0, -4.0, 0.0))  # frozen where the camera is: same picture
    same = _render(tmp_path, "frozen_here")
    diff = np.abs(same - live).max(-1)
    assert diff.mean() < 2e-3 and np.percentile(diff, 99.5) < 0.02
    api.freeze(ball, True, eye=(2.5, -3.0, 1.0))  # frozen elsewhere: reflections no longer follow this camera
    moved = _render(tmp_path, "frozen_there")
    assert (np.abs(moved - live).max(-1) > 0.05).mean() > 0.05
    api.freeze(ball, False)
    np.testing.assert_allclose(_render(tmp_path, "unfrozen"), live, atol=1e-6)


def test_eevee_renders_the_edit(chrome_ball, tmp_path):
    """EEVEE (Mesa llvmpipe in background mode here) renders the same node group without error:
    finite, not black, and the edit changes the picture inside its region."""
    ball, _ = chrome_ball
    sc = bpy.context.scene
    sc.render.engine = compat.eevee_engine()
    sc.eevee.taa_render_samples = 1
    api.add_mirror(ball)
    api.add_constraint(ball, (0.0, -1.0, 0.0), eye=(0.0, -4.0, 0.0))
    api.add_region(ball, "EUCLIDEAN", center=(0.0, -1.0, 0.0), radius=0.6, border=0.2)
    api.evaluate()
    assert api.install_render_nodes(ball) == 1
    identity = _render(tmp_path, "eevee_identity")
    ball.rokeby.constraints[0].target_handle.location.z += 3.0
    api.evaluate()
    edited = _render(tmp_path, "eevee_edited")
    for img in (identity, edited):
        assert np.isfinite(img).all() and img.mean() > 0.05
    changed = np.abs(edited - identity).max(-1) > 0.05
    ys, xs = np.mgrid[0:SIZE, 0:SIZE]
    half = 4.0 * 18.0 / 50.0
    r = np.hypot((xs + 0.5) / SIZE * 2 - 1, 1 - (ys + 0.5) / SIZE * 2) * half
    assert changed[r < 0.5].mean() > 0.3
    assert changed[r > 0.9].mean() < 0.02  # the background and the ball's rim stay


def test_red_handle_pixel_shows_the_green_handles_object(chrome_ball, tmp_path):
    """The constraint in pixels: where the red handle projects, the render shows the object the
    green handle sits on (a colour-coded emitter that the ball does not reflect there physically)."""
    from bpy_extras.object_utils import world_to_camera_view  # noqa: PLC0415
    from mathutils import Vector  # noqa: PLC0415

    ball, _ = chrome_ball
    sc = bpy.context.scene
    # A large green emitter up and to the left, facing the ball (above p's horizon); on a convex
    # mirror a small one would shrink to a pixel or two.
    bpy.ops.mesh.primitive_plane_add(size=6.0, location=(-3.5, -3.5, 3.0))
    lamp = bpy.context.object
    lamp.rotation_euler = Vector((3.5, 3.5, -3.0)).to_track_quat("Z", "Y").to_euler()
    glow = bpy.data.materials.new("Green glow")
    glow.use_nodes = True
    tree = glow.node_tree
    tree.nodes.remove(tree.nodes["Principled BSDF"])
    emit = tree.nodes.new("ShaderNodeEmission")
    emit.inputs["Color"].default_value = (0.0, 1.0, 0.0, 1.0)
    emit.inputs["Strength"].default_value = 5.0
    tree.links.new(emit.outputs["Emission"], tree.nodes["Material Output"].inputs["Surface"])
    lamp.data.materials.append(glow)
    p = np.array([0.35, -0.9, -0.25])
    p /= np.linalg.norm(p)
    bpy.context.view_layer.update()
    co = world_to_camera_view(sc, sc.camera, Vector(p))
    row, col = int((1.0 - co.y) * SIZE), int(co.x * SIZE)
    sc.view_settings.view_transform = "Standard"  # AgX would desaturate the bright green

    def at_handle(img):
        return img[::-1][row - 1:row + 2, col - 1:col + 2].reshape(-1, 3).mean(0)

    plain = at_handle(_render(tmp_path, "plain"))
    assert not (plain[1] > 2 * max(plain[0], plain[2]) and plain[1] > 0.5)  # not green physically
    api.add_mirror(ball)
    api.add_constraint(ball, p, tuple(lamp.location), eye=(0.0, -4.0, 0.0))
    api.add_region(ball, "EUCLIDEAN", center=tuple(p), radius=0.5, border=0.2)
    api.evaluate()
    api.install_render_nodes(ball)
    edited = at_handle(_render(tmp_path, "edited"))
    assert edited[1] > 2 * max(edited[0], edited[2]) and edited[1] > 0.5, edited
