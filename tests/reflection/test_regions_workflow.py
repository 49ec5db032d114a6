"""The everyday workflows around regions never lose an edit silently.

Problem 3, free-form regions: the region follows its vertex group when the group is renamed
(also after save and reload), when its reader modifier is applied (or the mirror converted to a
mesh), and a deleted group or an empty group name are reported naming the group or the argument.
Problem 4, geodesic distances on a mesh of several pieces (the shared teapot: body, lid, knob,
spout): a piece no constraint reaches follows one rule for any number of constraints.
"""

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import rokeby  # noqa: E402
from rokeby import api  # noqa: E402
from rokeby.reflection import mirror_state  # noqa: E402
from rokeby.core.meshio import load_obj  # noqa: E402
from rokeby.reflection import freeform_regions  # noqa: E402
from rokeby.core import schema  # noqa: E402

from support import cycles, mesh_path  # noqa: E402


@pytest.fixture(autouse=True)
def registered():
    bpy.ops.wm.read_homefile(use_empty=True)
    rokeby.register()
    mirror_state.reset()
    yield


def _camera(sc, location=(0.0, -6.0, 0.0)):
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    sc.collection.objects.link(cam)
    sc.camera = cam
    cam.location = location
    cam.rotation_euler = (math.pi / 2, 0.0, 0.0)
    return cam


def _angle(q):
    return 2.0 * np.arccos(np.clip(np.abs(np.asarray(q, np.float64)[:, 3]), 0.0, 1.0))


def _quat_diff(a, b):
    """Angle between two fields of unit quaternions, per vertex (radians)."""
    d = np.abs(np.einsum("ij,ij->i", np.asarray(a, np.float64), np.asarray(b, np.float64)))
    return 2.0 * np.arccos(np.clip(d, 0.0, 1.0))


# --- problem 3: free-form regions ----------------------------------------------------------------


def _ball():
    """A chrome ball with a painted patch on its front (the side the camera sees), a constraint
    in the patch and a free-form region on it."""
    sc = bpy.context.scene
    bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16)
    ball = bpy.context.object
    ball.name = "Ball"
    mat = bpy.data.materials.new("Chrome")
    mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Metallic"].default_value = 1.0
    bsdf.inputs["Roughness"].default_value = 0.0
    ball.data.materials.append(mat)
    co = np.empty(len(ball.data.vertices) * 3, np.float32)
    ball.data.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    patch = np.flatnonzero(co[:, 1] < -0.5)  # the front cap, facing the camera at -y
    ball.vertex_groups.new(name="Patch").add(patch.tolist(), 1.0, "REPLACE")
    _camera(sc)
    world = bpy.data.worlds.new("World")
    world.use_nodes = True
    sc.world = world
    grad = world.node_tree.nodes.new("ShaderNodeTexGradient")  # a world that changes with direction
    coord = world.node_tree.nodes.new("ShaderNodeTexCoord")
    world.node_tree.links.new(coord.outputs["Generated"], grad.inputs["Vector"])
    world.node_tree.links.new(grad.outputs["Color"], world.node_tree.nodes["Background"].inputs["Color"])
    api.add_mirror(ball)
    api.add_constraint(ball, (0.0, -1.0, 0.0), (0.8, -5.0, 0.8), eye=(0.0, -6.0, 0.0))
    api.add_region(ball, "FREEFORM", vertex_group="Patch", border=0.1)
    rep = api.evaluate()["Ball"]
    assert rep.status == "OK", rep.summary()
    return ball, patch


def _repainted(ob):
    """What weight painting in a window does: the object's geometry is tagged, and the depsgraph
    handler re-reads it; then the API brings the mirror up to date (settling a remade reader)."""
    ob.update_tag()
    bpy.context.view_layer.update()
    return api.evaluate()[ob.name]


def _render(path):
    sc = cycles(bpy.context.scene, 24, 4)
    sc.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(str(path))
    px = np.array(img.pixels[:], np.float32).reshape(24, 24, 4)[..., :3]
    bpy.data.images.remove(img)
    return px


def test_empty_group_name_is_refused_naming_the_argument():
    ball, _ = _ball()
    n_mods, n_regions = len(ball.modifiers), len(ball.rokeby.regions)
    with pytest.raises(api.RokebyError) as err:
        api.add_region(ball, "FREEFORM")
    msg = str(err.value)
    assert msg.startswith("vertex_group:"), msg
    assert "''" not in msg and "'Patch'" in msg, msg  # names the groups there are, not an empty one
    with pytest.raises(api.RokebyError, match="no vertex group 'Nope' \\(it has 'Patch'\\)"):
        api.add_region(ball, "FREEFORM", vertex_group="Nope")
    assert len(ball.modifiers) == n_mods and len(ball.rokeby.regions) == n_regions


def test_renamed_vertex_group_is_followed_and_keeps_following(tmp_path):
    ball, patch = _ball()
    before = api.field(ball).copy()
    assert _angle(before[patch]).max() > 0.05  # the edit shows in the patch
    ball.vertex_groups["Patch"].name = "Shine"
    rep = api.evaluate()["Ball"]
    assert rep.status == "OK", rep.summary()  # the old main: ERROR for the whole mirror
    rg = ball.rokeby.regions[0]
    assert rg.vertex_group == "Shine"
    assert freeform_regions.find_reader(ball, "Shine") is not None and freeform_regions.find_reader(ball, "Patch") is None
    assert [m.name for m in ball.modifiers if m.name.startswith(schema.VG_MODIFIER_PREFIX)] == [schema.VG_MODIFIER_PREFIX + "Shine"]
    np.testing.assert_allclose(api.field(ball), before, atol=1e-6)
    # Saved and reloaded, the next rename is followed too, and so is the painting.
    path = str(tmp_path / "renamed.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    ball = bpy.data.objects["Ball"]
    ball.vertex_groups["Shine"].name = "Gloss"
    rep = api.evaluate()["Ball"]
    assert rep.status == "OK" and ball.rokeby.regions[0].vertex_group == "Gloss", rep.summary()
    np.testing.assert_allclose(api.field(ball), before, atol=1e-6)
    ball.vertex_groups["Gloss"].add(patch.tolist(), 0.0, "REPLACE")  # erase the painting
    rep = _repainted(ball)
    assert rep.status == "OK", rep.summary()
    assert _angle(api.field(ball)).max() < 1e-6  # no weight left: the edit is gone


def test_rename_in_a_window_is_followed_through_the_depsgraph_handler():
    """The handler path: the update after the rename repoints the reader and reads the weights
    again in the same update (Blender would not call the handler for the modifier change)."""
    ball, patch = _ball()
    before = api.field(ball).copy()
    ball.vertex_groups["Patch"].name = "Shine"
    ball.update_tag()
    bpy.context.view_layer.update()  # depsgraph_update_post → the evaluator
    rep = api.report(ball)
    assert rep.status == "OK" and not rep.pending, rep.summary()
    assert ball.rokeby.regions[0].vertex_group == "Shine"
    np.testing.assert_allclose(api.field(ball), before, atol=1e-6)
    ball.vertex_groups["Shine"].add(patch.tolist(), 0.0, "REPLACE")  # and the painting is followed
    ball.update_tag()
    bpy.context.view_layer.update()
    assert api.report(ball).status == "OK" and _angle(api.field(ball)).max() < 1e-6


def test_applied_reader_modifier_is_remade_and_the_region_follows_the_painting(tmp_path):
    ball, patch = _ball()
    edited = _render(tmp_path / "edited.png")
    name = schema.VG_MODIFIER_PREFIX + "Patch"
    with bpy.context.temp_override(object=ball, active_object=ball):
        assert bpy.ops.object.modifier_apply(modifier=name) == {"FINISHED"}
    ball.vertex_groups["Patch"].add(patch.tolist(), 0.0, "REPLACE")  # erase every weight
    rep = _repainted(ball)
    assert rep.status == "OK", rep.summary()
    assert _angle(api.field(ball)).max() < 1e-6  # the old main kept the baked weights: the edit stayed
    assert name in ball.modifiers  # remade
    assert (schema.REGION_ATTRIBUTE_PREFIX + "Patch") not in ball.data.attributes  # the frozen copy is gone
    erased = _render(tmp_path / "erased.png")
    ball.rokeby.render_edits = False
    api.evaluate()
    physical = _render(tmp_path / "physical.png")
    assert np.abs(edited - physical).max() > 0.05  # the edit was visible
    np.testing.assert_allclose(erased, physical, atol=1e-4)  # and is gone from the render


def test_convert_to_mesh_keeps_the_region_live():
    ball, patch = _ball()
    before = api.field(ball).copy()
    with bpy.context.temp_override(object=ball, active_object=ball, selected_objects=[ball], selected_editable_objects=[ball]):
        bpy.ops.object.convert(target="MESH")
    ball = bpy.data.objects["Ball"]
    rep = api.evaluate()["Ball"]
    assert rep.status == "OK", rep.summary()
    np.testing.assert_allclose(api.field(ball), before, atol=1e-6)
    half = patch[: len(patch) // 2]
    ball.vertex_groups["Patch"].add(half.tolist(), 0.0, "REPLACE")
    _repainted(ball)
    q = api.field(ball)
    assert _angle(q[half]).max() < 1e-6 and _angle(q[patch[len(patch) // 2:]]).max() > 0.01


def test_deleted_group_warns_naming_it_and_the_status_says_what_renders_show():
    ball, patch = _ball()
    ball.vertex_groups.remove(ball.vertex_groups["Patch"])
    rep = api.evaluate()["Ball"]
    assert rep.status == "WARNING", rep.summary()  # the old main: ERROR, renders kept the old field
    assert any("'Patch'" in m and "left out" in m for m in rep.messages), rep.summary()
    # Left out: the constraint acts on the whole ball now, as the status says.
    outside = np.setdiff1d(np.arange(len(ball.data.vertices)), patch)
    assert _angle(api.field(ball)[outside]).min() > 0.01
    stored = api.stored_field(ball)
    np.testing.assert_allclose(mirror_state.quaternions(stored), api.field(ball), atol=1e-5)
    assert not [m for m in ball.modifiers if m.name.startswith(schema.VG_MODIFIER_PREFIX)]  # its reader went


def test_choosing_another_group_in_the_sidebar_reads_that_group():
    ball, patch = _ball()
    co = np.array([v.co for v in ball.data.vertices])
    core = np.flatnonzero(co[:, 1] < -0.9)  # a smaller patch around the constraint
    ball.vertex_groups.new(name="Core").add(core.tolist(), 1.0, "REPLACE")
    ball.rokeby.regions[0].vertex_group = "Core"  # what the sidebar's search field sets
    rep = api.evaluate()["Ball"]
    assert rep.status == "OK", rep.summary()
    q = api.field(ball)
    ring = np.setdiff1d(patch, core)
    far = ring[co[ring, 1] > -0.75]  # in Patch, well outside Core and its border
    assert _angle(q[core]).max() > 0.05 and _angle(q[far]).max() < 1e-6
    assert freeform_regions.find_reader(ball, "Core") is not None and freeform_regions.find_reader(ball, "Patch") is None


# --- problem 4: geodesic distances on a mesh of several pieces ----------------------------------


def _teapot():
    v, f = load_obj(mesh_path("teapot.obj"))
    v = np.asarray(v, np.float64)[:, [0, 2, 1]] * np.array([1.0, -1.0, 1.0])  # y-up → z-up
    me = bpy.data.meshes.new("Teapot")
    me.from_pydata(v.tolist(), [], np.asarray(f).tolist())
    me.update()
    ob = bpy.data.objects.new("Teapot", me)
    mat = bpy.data.materials.new("Chrome")
    mat.use_nodes = True
    mat.node_tree.nodes["Principled BSDF"].inputs["Metallic"].default_value = 1.0
    me.materials.append(mat)
    sc = bpy.context.scene
    sc.collection.objects.link(ob)
    _camera(sc, (0.0, -12.0, 1.5))
    # Its pieces: body with handle (z < 2.5), spout (x > 1.7), lid (z 2.4-2.7) and knob (above).
    lid = v[:, 2] > 2.75  # the knob, a piece of its own
    body = (v[:, 2] < 2.3) & (v[:, 0] < 1.6)
    api.add_mirror(ob, metric="GEODESIC")
    return ob, lid, body


def _nudged_constraint(ob, point, offset, eye):
    """A constraint whose green handle is moved a little off the physical reflection."""
    k = api.add_constraint(ob, point, eye=eye)
    green = ob.rokeby.constraints[k].target_handle
    green.location = tuple(np.array(green.location) + np.array(offset))
    return k


def test_pieces_no_constraint_reaches_follow_one_rule_for_any_number_of_constraints():
    """Adding a second constraint on the body must not un-edit the lid: for K = 1 and K = 2 the
    pieces no constraint reaches take the field of straight-line distances."""
    ob, lid, body = _teapot()
    eye = (0.0, -12.0, 1.5)
    _nudged_constraint(ob, (0.0, -2.0, 1.0), (1.0, 0.0, 1.0), eye)
    reports = []
    for k in (1, 2):
        if k == 2:
            _nudged_constraint(ob, (1.4, -1.4, 0.6), (-1.0, 0.0, 0.6), eye)
        ob.rokeby.metric = "GEODESIC"
        rep = api.evaluate()["Teapot"]
        assert rep.status == "OK", rep.summary()
        geodesic = api.field(ob).copy()
        ob.rokeby.metric = "EUCLIDEAN"
        api.evaluate()
        euclidean = api.field(ob).copy()
        assert _angle(geodesic[lid]).min() > 0.02, k  # the lid keeps its edit (the old main, K = 2: none)
        assert _quat_diff(geodesic[lid], euclidean[lid]).max() < 1e-3, k  # by straight-line distance
        if k == 2:
            assert _quat_diff(geodesic[body], euclidean[body]).max() > 3e-3  # the body blends geodesically
        reports.append(rep)
        stored = mirror_state.quaternions(api.stored_field(ob))
        assert np.isfinite(stored).all()
    for rep in reports:  # the status says how many pieces no constraint reaches, for K = 1 and 2
        assert rep.unreached_pieces == (3, 4), rep.unreached_pieces  # lid, knob and spout
        assert any("3 of 4 pieces" in m for m in rep.messages), rep.summary()


def test_unreached_rule_inside_a_region():
    """With a region, its constraints form the group: a piece inside the region that none of them
    reaches takes their straight-line blend, for one constraint or two."""
    ob, lid, _ = _teapot()
    eye = (0.0, -12.0, 1.5)
    api.add_region(ob, "EUCLIDEAN", center=(0.0, 0.0, 1.0), radius=6.0, border=0.5)
    _nudged_constraint(ob, (0.0, -2.0, 1.0), (1.0, 0.0, 1.0), eye)
    _nudged_constraint(ob, (1.4, -1.4, 0.6), (-1.0, 0.0, 0.6), eye)
    rep = api.evaluate()["Teapot"]
    assert rep.status == "OK", rep.summary()
    geodesic = api.field(ob).copy()
    ob.rokeby.metric = "EUCLIDEAN"
    api.evaluate()
    assert _angle(geodesic[lid]).min() > 0.02
    assert _quat_diff(geodesic[lid], api.field(ob)[lid]).max() < 1e-3


def test_fallback_helpers():
    """The rule as the evaluator applies it to the (K, V) distances, and the piece labels."""
    from rokeby.reflection import unreached_pieces  # noqa: PLC0415

    tri = np.array([[0, 1, 2], [1, 3, 2], [4, 5, 6]])
    labels = unreached_pieces.mesh_pieces(tri, 8)
    np.testing.assert_array_equal(labels, [0, 0, 0, 0, 4, 4, 4, -1])
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [5, 0, 0], [6, 0, 0], [5, 1, 0], [9, 9, 9]], np.float32)
    rows = np.zeros((2, 9), np.float32)
    rows[:, :3] = v[[0, 3]]
    inf = np.inf
    d = np.array([[0, 1, 1, 1.4, inf, inf, inf, inf], [1.4, 1, 1, 0, inf, inf, inf, inf]], np.float32)
    out = unreached_pieces.unreached_fallback(d, rows, v)
    np.testing.assert_array_equal(out[:, :4], d[:, :4])  # reached: geodesic as it was
    np.testing.assert_allclose(out[:, 4:], np.linalg.norm(v[None, 4:] - rows[:, None, :3], axis=2), rtol=1e-6)
    assert np.isinf(d[:, 4:]).all()  # the cached input is not modified
    # Two regions sharing constraint 1: where group {0, 1} is reached (by 0), constraint 1 keeps +inf.
    d2 = d.copy()
    d2[1, :4] = inf
    regions = [{"kind": "weights", "values": None, "at_constraints": np.array([1.0, 1.0])},
               {"kind": "weights", "values": None, "at_constraints": np.array([0.0, 1.0])}]
    out = unreached_pieces.unreached_fallback(d2, rows, v, regions)
    assert np.isinf(out[1, :4]).all() and np.isfinite(out[:, 4:7]).all()
