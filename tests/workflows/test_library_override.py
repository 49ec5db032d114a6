"""A mirror in a linked asset and its library override in one scene: the override is
a mirror of its own and evaluates (it is found by identity rather than by name, which it shares
with the linked original); the linked original cannot store a field and says so; nothing
raises."""

import bpy
import numpy as np
import pytest

import rokeby
from rokeby import api
from rokeby.reflection import mirror_state, scene_inputs


@pytest.fixture
def linked_and_override(tmp_path):
    rokeby.register()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    rokeby.register()
    sc = bpy.context.scene
    asset = bpy.data.collections.new("Asset")
    sc.collection.children.link(asset)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0)
    ball = bpy.context.object
    ball.name = "Ball"
    for c in ball.users_collection:
        c.objects.unlink(ball)
    asset.objects.link(ball)
    api.add_mirror(ball)
    api.add_constraint(ball, (0.0, -1.0, 0.0), (1.0, -3.0, 2.0), eye=(0.0, -5.0, 0.0))
    for ob in list(bpy.data.objects):  # the handles travel with the asset
        if ob is not ball:
            for c in ob.users_collection:
                c.objects.unlink(ob)
            asset.objects.link(ob)
    api.evaluate()
    lib = tmp_path / "asset.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(lib))

    bpy.ops.wm.read_factory_settings(use_empty=True)
    rokeby.register()
    sc = bpy.context.scene
    with bpy.data.libraries.load(str(lib), link=True) as (_src, dst):
        dst.collections = ["Asset"]
    linked = dst.collections[0]
    sc.collection.children.link(linked)  # the linked asset as it is ...
    linked.override_hierarchy_create(sc, bpy.context.view_layer)  # ... and an override beside it
    bpy.context.view_layer.update()
    balls = [o for o in bpy.data.objects if o.name == "Ball"]
    original = next(o for o in balls if o.library is not None)
    override = next(o for o in balls if o.override_library is not None)
    yield sc, original, override
    bpy.ops.wm.read_factory_settings(use_empty=True)


def test_the_override_mirror_evaluates_and_the_linked_one_is_read_only(linked_and_override):
    sc, original, override = linked_and_override
    reps = api.evaluate(force=True)  # raised AttributeError before (a carrier on the linked mirror)
    rep = reps["Ball"]
    assert mirror_state.report_of(override) is rep
    assert "deleted" not in rep.summary() and rep.status != "ERROR", rep.summary()
    assert rep.constraints_used == 1
    # Its mesh is the asset's (linked, shared with the original): the field lives in a carrier.
    assert rep.field_mesh == "transfer"
    field = api.field(override)
    assert field is not None and np.isfinite(field).all() and np.abs(field).max() > 0.01
    # The linked original cannot store a field for this scene: an error saying so, listed under
    # its library's file name (the plain name is the override's).
    note = reps["Ball (asset.blend)"]
    assert mirror_state.report_of(original) is note
    assert note.status == "ERROR" and "linked from library" in note.summary() and "library override" in note.summary()
    # The scene's mirrors are found by identity: both are in it, the override is evaluated.
    assert {(o.library is not None) for o in scene_inputs.mirrors_of(sc)} == {True, False}
