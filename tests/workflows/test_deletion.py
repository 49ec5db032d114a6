"""Deleting any object the add-on uses, at any time: the mirror, every kind of handle,
region centres, the light of a highlight, the camera, the vertex group of a free-form region.
Afterwards evaluation, the sidebar, a render and undo all still work, nothing non-finite is
written, and the report says what is missing."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from rokeby import api  # noqa: E402
from support.scenes import add_front_camera, add_point_lamp, empty_scene  # noqa: E402
from support.ui import Layout  # noqa: E402


def _scene():
    sc = empty_scene()
    sc.render.engine = "CYCLES"
    sc.cycles.samples = 1
    sc.render.resolution_x = sc.render.resolution_y = 16
    bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16)
    ball = bpy.context.object
    ball.name = "Ball"
    mat = bpy.data.materials.new("Chrome")
    mat.use_nodes = True
    mat.node_tree.nodes["Principled BSDF"].inputs["Metallic"].default_value = 1.0
    ball.data.materials.append(mat)
    ball.vertex_groups.new(name="Patch").add(list(range(60)), 1.0, "REPLACE")
    add_front_camera(sc)
    lamp = add_point_lamp(sc)
    api.add_mirror(ball)
    api.add_constraint(ball, (0.0, -1.0, 0.0), (1.0, -3.0, 2.0))
    api.add_highlight_constraint(ball, lamp)
    api.add_constraint(ball, (0.3, -0.9, 0.2), kind="REFRACTION")
    api.add_region(ball, "EUCLIDEAN", center=(0.0, -1.0, 0.0), radius=0.8)
    api.add_region(ball, "GEODESIC", center=(0.2, -0.9, 0.3), radius=0.8)
    api.add_region(ball, "FREEFORM", vertex_group="Patch")
    api.evaluate()
    api.install_render_nodes(ball)
    bpy.ops.ed.undo_push(message="scene")
    return ball


def _used(ball):
    s = ball.rokeby
    return {
        "mirror": ball,
        "red handle": s.constraints[0].surface_handle,
        "green handle": s.constraints[0].target_handle,
        "highlight light": bpy.data.objects["Lamp"],
        "refraction green handle": s.constraints[2].target_handle,
        "euclidean region centre": s.regions[0].center,
        "geodesic region centre": s.regions[1].center,
        "camera": bpy.data.objects["Camera"],
    }


ROLES = [
    "mirror", "red handle", "green handle", "highlight light", "refraction green handle",
    "euclidean region centre", "geodesic region centre", "camera", "vertex group",
]


def _draw_panel():
    from rokeby.reflection.ui import ROKEBY_PT_main  # noqa: PLC0415

    log = []
    ROKEBY_PT_main.draw(type("P", (), {"layout": Layout(log)})(), bpy.context)
    return [t for kind, t in log if kind == "label"]


@pytest.mark.parametrize("role", ROLES)
def test_delete_anything_the_add_on_uses(role, tmp_path):
    ball = _scene()
    before = api.stored_field(ball).copy()
    if role == "vertex group":
        ball.vertex_groups.remove(ball.vertex_groups["Patch"])
    else:
        bpy.data.objects.remove(_used(ball)[role], do_unlink=True)
    reports = api.evaluate()  # must not raise
    ball = bpy.data.objects.get("Ball")
    if ball is not None:
        field = api.stored_field(ball)
        assert field is not None and np.isfinite(field).all()
        rep = reports["Ball"]
        if role in ("red handle", "green handle", "euclidean region centre", "geodesic region centre", "vertex group", "highlight light", "refraction green handle"):
            assert rep.status in ("WARNING", "ERROR") and rep.messages, (role, rep.summary())
        bpy.context.view_layer.objects.active = ball
    else:
        assert "Ball" not in reports
    labels = _draw_panel()  # the sidebar draws
    assert isinstance(labels, list)
    if role != "camera":
        bpy.context.scene.render.filepath = str(tmp_path / "after.png")
        bpy.ops.render.render(write_still=True)  # and renders
    # Undo brings the deleted object and the edit back.
    bpy.ops.ed.undo_push(message="delete")
    bpy.ops.ed.undo()
    ball = bpy.data.objects["Ball"]
    api.evaluate()
    np.testing.assert_allclose(api.stored_field(ball), before, atol=1e-5)
