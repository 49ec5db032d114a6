"""Shared meshes and duplicates (problem 1): no edit overwrites another object's.

Two mirrors sharing one mesh (Ctrl+L ▸ Link Object Data, Alt+D) used to write their fields into
the one mesh: the last evaluated won, and Remove Mirror on one deleted the other's field. Copies
(Shift+D, Alt+D) kept the original's handles. Here each is rendered in Cycles with the
direction-coded world of tests/reflection/test_wysiwyg.py: each pixel reads back the reflected direction
Cycles traced, compared with what the mirror's own preview evaluates there.
"""

import numpy as np
import pytest
from support.wysiwyg import EYE, angles_deg, directions, hit_mask, new_scene, physical, render, sphere

bpy = pytest.importorskip("bpy")

from rokeby import api  # noqa: E402
from rokeby.blender import compat  # noqa: E402
from rokeby.reflection import duplicates, guard, handlers, mirror_state  # noqa: E402
from rokeby.core import native, schema  # noqa: E402
from rokeby.reflection import field_carriers  # noqa: E402

LEFT, RIGHT = (-0.65, 0.0, 0.0), (0.65, 0.0, 0.0)
SCALE = 0.5


def _place(ob, where):
    ob.location = where
    ob.scale = (SCALE,) * 3
    ob.visible_glossy = False  # reflected rays see the world, not the other mirror


def _edit(mirror, centre, towards):
    """A constraint at the front of the ball at ``centre`` whose green handle lies along
    ``towards`` from it, inside a Euclidean region."""
    p = np.array(centre) + (0.0, -SCALE, 0.0)
    api.add_constraint(mirror, p, p + np.array(towards) * 2.0)
    api.add_region(mirror, "EUCLIDEAN", center=tuple(p), radius=0.45, border=0.25)


def _mask(layers, side):
    """Hit pixels of the ball on ``side`` (−1 left, +1 right), by the AOV position."""
    return hit_mask(layers) & (np.sign(layers["P"][..., 0]) == side)


def _agreement(mirror, layers, mask):
    """Angles between the rendered directions and ``mirror``'s own preview at ``mask``'s pixels
    (edited directions folded below the surface left out, as in test_wysiwyg.agreement)."""
    rows, dist, regions = mirror_state.state_of(mirror).field_inputs
    assert dist is None
    p = layers["P"][mask].astype(np.float32)
    n = layers["N"][mask]
    n = (n / np.linalg.norm(n, axis=-1, keepdims=True)).astype(np.float32)
    want = native.edited_directions(p, n, EYE, rows, **({"regions": regions} if regions else {}))
    above = (want * n).sum(-1) > 0.0
    return angles_deg(directions(layers)[mask], want)[above]


def _turned(layers, mask):
    """Angles between the rendered and the physical reflection at ``mask``'s pixels."""
    m, r = physical(layers)
    full = np.zeros(m.shape + (3,))
    full[m] = r
    return angles_deg(directions(layers)[mask], full[mask])


def _owns_its_field(mirror, layers, side):
    mask = _mask(layers, side)
    assert mask.sum() > 150
    ang = _agreement(mirror, layers, mask)
    assert np.percentile(ang, 99) < 1.0, (mirror.name, np.percentile(ang, 99))
    assert (_turned(layers, mask) > 5.0).mean() > 0.1  # and it is edited
    return mask


def test_two_mirrors_sharing_one_mesh_each_render_their_own_edit(tmp_path):
    new_scene()
    left = sphere(48, 24, "Left")
    right = bpy.data.objects.new("Right", left.data)  # Ctrl+L ▸ Link Object Data
    bpy.context.scene.collection.objects.link(right)
    _place(left, LEFT)
    _place(right, RIGHT)
    for ob in (left, right):
        api.add_mirror(ob)
    _edit(left, LEFT, (0.3, -1.0, 0.5))
    _edit(right, RIGHT, (-0.4, -1.0, -0.3))
    reports = api.evaluate()
    for name in ("Left", "Right"):
        assert reports[name].status != "ERROR" and reports[name].renders is True, reports[name].summary()
    layers = render(tmp_path, "both")
    # Before: the mirror evaluated last won, the other rendered its field (70° off its own).
    left_px = _owns_its_field(left, layers, -1)
    _owns_its_field(right, layers, 1)
    # Each carries its own field; the shared mesh holds none.
    assert reports["Left"].field_mesh == reports["Right"].field_mesh == "transfer"
    assert field_carriers.carrier_of(left) is not field_carriers.carrier_of(right)
    assert not any(left.data.attributes.get(n) for n in field_carriers.FIELD_ATTRIBUTES)

    # Saved and reopened: both fields are in the file, and render the same pixels.
    stored = {ob.name: api.stored_field(ob).copy() for ob in (left, right)}
    assert np.abs(stored["Left"] - stored["Right"]).max() > 0.05
    path = tmp_path / "shared.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.open_mainfile(filepath=str(path))
    left, right = bpy.data.objects["Left"], bpy.data.objects["Right"]
    assert left.data == right.data
    for ob in (left, right):  # read before anything re-evaluates
        np.testing.assert_array_equal(api.stored_field(ob), stored[ob.name])
    np.testing.assert_allclose(render(tmp_path, "reopened")["Combined"], layers["Combined"], atol=1e-5)

    # Remove Mirror on one: the other's render does not change; the removed one renders the
    # physical mirror, although it still shares the mesh and the material with an edited one.
    api.remove_mirror(right)
    assert field_carriers.carrier_of(left) is not None and not right.modifiers
    after = render(tmp_path, "removed")
    np.testing.assert_allclose(after["Combined"][left_px], layers["Combined"][left_px], atol=1e-5)
    assert np.percentile(_turned(after, _mask(after, 1)), 99) < 0.2
    assert api.evaluate()["Left"].status != "ERROR"
    # Linked to one object again (Make Single User on the other): the field goes back into the mesh.
    right.data = right.data.copy()
    rep = api.evaluate()["Left"]
    assert rep.field_mesh == "evaluated" and field_carriers.carrier_of(left) is None and not left.modifiers
    np.testing.assert_allclose(render(tmp_path, "single")["Combined"][left_px], layers["Combined"][left_px], atol=1e-5)


def _duplicate(ob, linked):
    bpy.ops.object.select_all(action="DESELECT")
    ob.select_set(True)
    bpy.context.view_layer.objects.active = ob
    assert bpy.ops.object.duplicate(linked=linked) == {"FINISHED"}
    return bpy.context.view_layer.objects.active


@pytest.mark.parametrize("linked", [False, True], ids=["shift-d", "alt-d"])
def test_a_copy_of_a_mirror_gets_its_own_handles_and_field(tmp_path, linked):
    new_scene()
    ball = sphere(48, 24, "Ball")
    _place(ball, LEFT)
    api.add_mirror(ball)
    _edit(ball, LEFT, (0.3, -1.0, 0.5))
    api.evaluate()
    before = render(tmp_path, "original")
    left_px = _owns_its_field(ball, before, -1)
    red, green = ball.rokeby.constraints[0].surface_handle, ball.rokeby.constraints[0].target_handle

    copy = _duplicate(ball, linked)
    assert (copy.data == ball.data) == linked
    copy.location = RIGHT
    reports = api.evaluate()
    assert reports[copy.name].status != "ERROR", reports[copy.name].summary()
    assert not any("kept on" in m for m in reports[copy.name].messages)
    c = copy.rokeby.constraints[0]
    # Its own handles, kept on the copy, where the original's sit relative to the original.
    assert c.surface_handle not in (red, green) and c.target_handle not in (red, green)
    assert copy.rokeby.regions[0].center != ball.rokeby.regions[0].center
    assert duplicates.shrinkwrap_target(c.surface_handle) == copy and duplicates.shrinkwrap_target(red) == ball
    shift = np.array(RIGHT) - np.array(LEFT)
    for mine, theirs in ((c.surface_handle, red), (c.target_handle, green)):
        np.testing.assert_allclose(np.array(mine.matrix_world.translation), np.array(theirs.matrix_world.translation) + shift, atol=1e-5)
    assert ball.rokeby.constraints[0].surface_handle == red  # the original is untouched
    # Moving the copy brings its handles (they are parented to it); the original's stay.
    copy.location.z += 0.1
    api.evaluate()
    assert abs(c.surface_handle.matrix_world.translation.z - red.matrix_world.translation.z - 0.1) < 1e-5
    copy.location.z -= 0.1
    api.evaluate()

    layers = render(tmp_path, "copy")
    np.testing.assert_allclose(layers["Combined"][left_px], before["Combined"][left_px], atol=1e-5)
    _owns_its_field(copy, layers, 1)
    # The same edit relative to each ball: the same e at translated surface points.
    rows_a, rows_b = mirror_state.state_of(ball).field_inputs[0], mirror_state.state_of(copy).field_inputs[0]
    np.testing.assert_allclose(rows_b[:, :3], rows_a[:, :3] + shift, atol=1e-4)
    np.testing.assert_allclose(rows_b[:, 6:], rows_a[:, 6:], atol=1e-4)

    # Removing the copy's mirror leaves the original's render and handles as they were.
    api.remove_mirror(copy)
    assert red.name in bpy.data.objects and green.name in bpy.data.objects
    assert duplicates.shrinkwrap_target(red) == ball
    after = render(tmp_path, "copy-removed")
    np.testing.assert_allclose(after["Combined"][left_px], before["Combined"][left_px], atol=1e-5)
    assert np.percentile(_turned(after, _mask(after, 1)), 99) < 0.2


def test_handles_duplicated_with_the_mirror_stay_as_blender_made_them():
    """Selected together with its handles, a copy already points at the new handles (Blender
    remaps them): nothing more is made."""
    new_scene()
    ball = sphere(24, 12, "Ball")
    api.add_mirror(ball)
    api.add_constraint(ball, (0.0, -1.0, 0.0), (0.5, -3.0, 1.0))
    api.evaluate()
    c0 = ball.rokeby.constraints[0]
    bpy.ops.object.select_all(action="DESELECT")
    for ob in (ball, c0.surface_handle, c0.target_handle):
        ob.select_set(True)
    bpy.context.view_layer.objects.active = ball
    bpy.ops.object.duplicate()
    copy = bpy.context.view_layer.objects.active
    count = len(bpy.data.objects)
    api.evaluate()
    assert len(bpy.data.objects) == count
    red = copy.rokeby.constraints[0].surface_handle
    assert red != c0.surface_handle and duplicates.shrinkwrap_target(red) == copy and red.parent is None


def test_copies_of_a_subdivided_mirror_never_share_its_carrier():
    new_scene()
    ball = sphere(16, 8, "Ball")
    ball.modifiers.new("Subdivision", "SUBSURF").levels = 2
    api.add_mirror(ball)
    api.add_constraint(ball, (0.0, -1.0, 0.0), (0.6, -3.0, 1.0))
    api.evaluate()
    carrier = field_carriers.carrier_of(ball)
    assert carrier is not None
    for linked in (False, True):
        copy = _duplicate(ball, linked)
        copy.location.x += 3.0
        api.evaluate()
        copy.rokeby.constraints[0].target_handle.location.z -= 1.0  # its own edit now
        api.evaluate()
        mine = field_carriers.carrier_of(copy)
        assert mine is not None and mine is not carrier and field_carriers.carrier_of(ball) is carrier
        mod = copy.modifiers[schema.TRANSFER_MODIFIER]
        source = next(i.identifier for i in mod.node_group.interface.items_tree if getattr(i, "in_out", "") == "INPUT" and i.name == "Source")
        assert compat.modifier_input(mod, source) == mine
        assert compat.modifier_input(ball.modifiers[schema.TRANSFER_MODIFIER], source) == carrier
        # Each carrier holds its own mirror's field.
        for ob in (ball, copy):
            np.testing.assert_allclose(api.stored_field(ob), mirror_state.state_of(ob).rotations, atol=1e-6)
        api.remove_mirror(copy)
        assert field_carriers.carrier_of(ball) is carrier and carrier.name in bpy.data.objects
        np.testing.assert_allclose(api.stored_field(ball), mirror_state.state_of(ball).rotations, atol=1e-6)


def test_a_carrier_saved_without_an_owner_is_claimed_by_its_mirror_at_load():
    """Files saved before copies were handled: a copy may point at the original's carrier, which
    has no owner. The load-time migration gives it to the mirror it is named after."""
    new_scene()
    ball = sphere(16, 8, "Ball")
    ball.modifiers.new("Subdivision", "SUBSURF").levels = 1
    api.add_mirror(ball)
    api.add_constraint(ball, (0.0, -1.0, 0.0), (0.6, -3.0, 1.0))
    api.evaluate()
    carrier = field_carriers.carrier_of(ball)
    copy = bpy.data.objects.new("Ball copy", ball.data.copy())
    bpy.context.scene.collection.objects.link(copy)
    for mod in ball.modifiers:
        if mod.type == "SUBSURF":
            copy.modifiers.new(mod.name, "SUBSURF").levels = 1
    with guard.suspended():
        copy.rokeby.is_mirror = True
        copy.rokeby.field_carrier = carrier
        carrier.parent = None  # as saved by the previous version
    handlers.migrate_file()
    assert carrier.parent == ball
    assert field_carriers.carrier_of(copy) is None and field_carriers.carrier_of(ball) is carrier
    api.evaluate()
    assert field_carriers.carrier_of(copy) not in (None, carrier)


def test_a_red_handle_kept_on_another_object_is_reported():
    new_scene()
    ball = sphere(24, 12, "Ball")
    other = sphere(8, 4, "Other")
    other.location.x = 3.0
    api.add_mirror(ball)
    api.add_constraint(ball, (0.0, -1.0, 0.0), (0.5, -3.0, 1.0))
    red = ball.rokeby.constraints[0].surface_handle
    red.constraints[0].target = other  # not a mirror: no copy to separate, but not silent either
    rep = api.evaluate()["Ball"]
    assert rep.status == "WARNING" and any(f"is kept on 'Other'" in m for m in rep.messages), rep.summary()


def _evaluated_attribute(ob, name):
    me = ob.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
    attr = me.attributes.get(name)
    if attr is None:
        return None
    out = np.empty(len(attr.data) * 3, dtype=np.float32)
    attr.data.foreach_get("vector", out)
    return out.reshape(-1, 3)


def test_refraction_fields_of_mirrors_sharing_a_mesh_stay_their_own():
    """The refraction field (rokeby_refraction, what the refraction render nodes read) is carried
    per object too: each object's evaluated mesh has its own; none has one it did not make."""
    new_scene()
    left = sphere(24, 12, "Left")
    right = bpy.data.objects.new("Right", left.data)
    bpy.context.scene.collection.objects.link(right)
    _place(left, LEFT)
    _place(right, RIGHT)
    for ob, centre, dz in ((left, LEFT, 0.4), (right, RIGHT, -0.4)):
        api.add_mirror(ob)
        api.add_constraint(ob, np.array(centre) + (0.0, -SCALE, 0.0), eye=EYE, kind="REFRACTION")
        ob.rokeby.constraints[0].target_handle.location.z += dz
    reports = api.evaluate()
    assert all(r.status != "ERROR" for r in reports.values()), [r.summary() for r in reports.values()]
    fields = {}
    for ob in (left, right):
        own = mirror_state.state_of(ob).refractions
        assert own is not None and np.abs(own).max() > 0.02
        np.testing.assert_allclose(_evaluated_attribute(ob, schema.REFRACTION_ATTRIBUTE), own, atol=1e-6)
        np.testing.assert_allclose(api.stored_refraction(ob), own, atol=1e-6)
        fields[ob.name] = own
    assert np.abs(fields["Left"] - fields["Right"]).max() > 0.02
    # Without refraction constraints the right one's refraction field is gone; the left's stays.
    api.remove_constraint(right, 0)
    api.evaluate()
    gone = _evaluated_attribute(right, schema.REFRACTION_ATTRIBUTE)
    assert gone is None or not np.abs(gone).any()  # zeros read as no attribute: the identity
    assert api.stored_refraction(right) is None
    np.testing.assert_allclose(_evaluated_attribute(left, schema.REFRACTION_ATTRIBUTE), fields["Left"], atol=1e-6)
